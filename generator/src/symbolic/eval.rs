//! f64 evaluation of expressions: the generic (interpreted) side of uavgen.
//!
//! A [`Tape`] is the reachable part of the DAG flattened into instructions in
//! topological order; evaluating it is a single pass over a value buffer.

use super::expr::{Func, Graph, Id, Node};

#[derive(Clone, Copy, Debug)]
enum Op {
    Const(f64),
    Var(usize),
    Add(usize, usize),
    Mul(usize, usize),
    Neg(usize),
    Recip(usize),
    Powi(usize, i32),
    Sin(usize),
    Cos(usize),
    Sqrt(usize),
}

/// Flattened evaluation program for a set of output expressions.
#[derive(Clone, Debug)]
pub struct Tape {
    ops: Vec<Op>,
    outputs: Vec<usize>,
    n_vars: usize,
}

impl Tape {
    pub fn new(g: &Graph, outputs: &[Id]) -> Self {
        let order = g.reachable(outputs);
        let mut slot = vec![usize::MAX; g.len()];
        let mut ops = Vec::with_capacity(order.len());
        for (k, &id) in order.iter().enumerate() {
            slot[id.index()] = k;
            let s = |i: Id| slot[i.index()];
            ops.push(match g.node(id) {
                Node::Const(bits) => Op::Const(f64::from_bits(bits)),
                Node::Var(v) => Op::Var(v as usize),
                Node::Add(a, b) => Op::Add(s(a), s(b)),
                Node::Mul(a, b) => Op::Mul(s(a), s(b)),
                Node::Neg(a) => Op::Neg(s(a)),
                Node::Recip(a) => Op::Recip(s(a)),
                Node::Powi(a, n) => Op::Powi(s(a), n),
                Node::Call(Func::Sin, a) => Op::Sin(s(a)),
                Node::Call(Func::Cos, a) => Op::Cos(s(a)),
                Node::Call(Func::Sqrt, a) => Op::Sqrt(s(a)),
            });
        }
        let outputs = outputs.iter().map(|o| slot[o.index()]).collect();
        Self {
            ops,
            outputs,
            n_vars: g.var_count(),
        }
    }

    pub fn n_outputs(&self) -> usize {
        self.outputs.len()
    }

    /// Evaluate all outputs at `vars` (one value per graph variable).
    pub fn eval(&self, vars: &[f64]) -> Vec<f64> {
        assert_eq!(vars.len(), self.n_vars, "wrong number of variables");
        // The value buffer is reused between calls (a model's f is evaluated millions of times
        // by identify and evaluate; allocating it every time cost a fifth of the run).
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut v) => self.run(vars, &mut v),
            Err(_) => self.run(vars, &mut Vec::new()),
        })
    }

    /// [`Tape::eval`] into `out` (one value per output), without allocating.
    pub fn eval_into(&self, vars: &[f64], out: &mut [f64]) {
        assert_eq!(vars.len(), self.n_vars, "wrong number of variables");
        assert_eq!(out.len(), self.outputs.len(), "wrong number of outputs");
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut v) => self.run_into(vars, &mut v, out),
            Err(_) => self.run_into(vars, &mut Vec::new(), out),
        })
    }

    /// [`Tape::eval_into`], keeping every instruction's value in `values` (for [`Partial::gather`]).
    pub fn eval_values(&self, vars: &[f64], values: &mut Vec<f64>, out: &mut [f64]) {
        assert_eq!(vars.len(), self.n_vars, "wrong number of variables");
        assert_eq!(out.len(), self.outputs.len(), "wrong number of outputs");
        self.run_into(vars, values, out);
    }

    fn run(&self, vars: &[f64], v: &mut Vec<f64>) -> Vec<f64> {
        let mut out = vec![0.0; self.outputs.len()];
        self.run_into(vars, v, &mut out);
        out
    }

    fn run_into(&self, vars: &[f64], v: &mut Vec<f64>, out: &mut [f64]) {
        v.clear();
        v.reserve(self.ops.len());
        for &op in &self.ops {
            let value = apply(op, v, vars);
            v.push(value);
        }
        for (o, &slot) in out.iter_mut().zip(&self.outputs) {
            *o = v[slot];
        }
    }

    /// The part of the tape that depends on the variables `vars` ([`Partial`]).
    pub fn partial(&self, vars: &[usize]) -> Partial {
        let mut dependent = vec![false; self.ops.len()];
        let mut local = vec![usize::MAX; self.ops.len()];
        let mut frontier = Vec::new();
        let mut ops = Vec::new();
        for (k, op) in self.ops.iter().enumerate() {
            let operands: &[usize] = match op {
                Op::Const(_) => &[],
                Op::Var(i) => {
                    dependent[k] = vars.contains(i);
                    &[]
                }
                Op::Add(a, b) | Op::Mul(a, b) => &[*a, *b],
                Op::Neg(a) | Op::Recip(a) | Op::Powi(a, _) | Op::Sin(a) | Op::Cos(a) | Op::Sqrt(a) => {
                    std::slice::from_ref(a)
                }
            };
            if !dependent[k] && operands.iter().any(|&a| dependent[a]) {
                dependent[k] = true;
            }
            if dependent[k] {
                ops.push((k, *op));
            }
        }
        // The frontier: instructions that do not depend on `vars` but are read by ones that do.
        for &(_, op) in &ops {
            for a in op_operands(op) {
                if !dependent[a] && local[a] == usize::MAX {
                    local[a] = frontier.len();
                    frontier.push(a);
                }
            }
        }
        let f = frontier.len();
        for (i, &(k, _)) in ops.iter().enumerate() {
            local[k] = f + i;
        }
        let ops: Vec<Op> = ops.into_iter().map(|(_, op)| renumber(op, &local)).collect();
        let outputs = self
            .outputs
            .iter()
            .enumerate()
            .filter(|(_, &o)| dependent[o])
            .map(|(i, &o)| (i, local[o]))
            .collect();
        Partial { frontier, ops, outputs }
    }
}

#[inline(always)]
fn apply(op: Op, v: &[f64], vars: &[f64]) -> f64 {
    match op {
        Op::Const(c) => c,
        Op::Var(i) => vars[i],
        Op::Add(a, b) => v[a] + v[b],
        Op::Mul(a, b) => v[a] * v[b],
        Op::Neg(a) => -v[a],
        Op::Recip(a) => 1.0 / v[a],
        Op::Powi(a, n) => v[a].powi(n),
        Op::Sin(a) => v[a].sin(),
        Op::Cos(a) => v[a].cos(),
        Op::Sqrt(a) => v[a].sqrt(),
    }
}

fn op_operands(op: Op) -> impl Iterator<Item = usize> {
    let (a, b) = match op {
        Op::Const(_) | Op::Var(_) => (None, None),
        Op::Add(a, b) | Op::Mul(a, b) => (Some(a), Some(b)),
        Op::Neg(a) | Op::Recip(a) | Op::Powi(a, _) | Op::Sin(a) | Op::Cos(a) | Op::Sqrt(a) => (Some(a), None),
    };
    a.into_iter().chain(b)
}

fn renumber(op: Op, local: &[usize]) -> Op {
    let s = |a: usize| local[a];
    match op {
        Op::Const(c) => Op::Const(c),
        Op::Var(i) => Op::Var(i),
        Op::Add(a, b) => Op::Add(s(a), s(b)),
        Op::Mul(a, b) => Op::Mul(s(a), s(b)),
        Op::Neg(a) => Op::Neg(s(a)),
        Op::Recip(a) => Op::Recip(s(a)),
        Op::Powi(a, n) => Op::Powi(s(a), n),
        Op::Sin(a) => Op::Sin(s(a)),
        Op::Cos(a) => Op::Cos(s(a)),
        Op::Sqrt(a) => Op::Sqrt(s(a)),
    }
}

/// The instructions of a [`Tape`] that depend on some of its variables, for evaluating it many
/// times at points that differ only in those variables (a scan over one input of a model): the
/// values of the other instructions they read (the frontier) are gathered once per point from a
/// full evaluation ([`Tape::eval_values`]), and [`Partial::eval`] recomputes the dependent
/// instructions alone, in the tape's order — the outputs are bit for bit the full tape's.
#[derive(Clone, Debug)]
pub struct Partial {
    /// Slots of the full tape read by the dependent instructions.
    frontier: Vec<usize>,
    /// The dependent instructions; operand k < frontier.len() is frontier value k, else the result
    /// of instruction k − frontier.len().
    ops: Vec<Op>,
    /// (output index, local slot) of the outputs that depend on the variables.
    outputs: Vec<(usize, usize)>,
}

impl Partial {
    /// Frontier values per point.
    pub fn frontier_len(&self) -> usize {
        self.frontier.len()
    }

    /// Whether output i depends on the variables.
    pub fn depends(&self, i: usize) -> bool {
        self.outputs.iter().any(|&(o, _)| o == i)
    }

    /// Append the frontier values of a full evaluation (`values` of [`Tape::eval_values`]).
    pub fn gather(&self, values: &[f64], into: &mut Vec<f64>) {
        into.extend(self.frontier.iter().map(|&k| values[k]));
    }

    /// The tape at `vars` (all variables; only the partial's are read besides the frontier),
    /// `frontier` gathered at a point equal in every other variable: overwrites the outputs that
    /// depend on the variables in `out` (the others keep their values). `scratch` is reused.
    pub fn eval(&self, frontier: &[f64], vars: &[f64], scratch: &mut Vec<f64>, out: &mut [f64]) {
        scratch.clear();
        scratch.extend_from_slice(frontier);
        for &op in &self.ops {
            let x = apply(op, scratch, vars);
            scratch.push(x);
        }
        for &(o, slot) in &self.outputs {
            out[o] = scratch[slot];
        }
    }
}

std::thread_local! {
    static SCRATCH: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::symbolic::diff::diff;

    #[test]
    fn evaluates_and_differentiates_by_hand() {
        // e = x² sin(y) + 1/x ; ∂e/∂x = 2x sin y − 1/x² ; ∂e/∂y = x² cos y
        let mut g = Graph::new();
        let x = g.var("x");
        let y = g.var("y");
        let x2 = g.powi(x, 2);
        let sy = g.sin(y);
        let a = g.mul(x2, sy);
        let rx = g.recip(x);
        let e = g.add(a, rx);
        let dx = diff(&mut g, e, 0);
        let dy = diff(&mut g, e, 1);
        let tape = Tape::new(&g, &[e, dx, dy]);
        let (xv, yv) = (1.7_f64, -0.4_f64);
        let out = tape.eval(&[xv, yv]);
        assert!((out[0] - (xv * xv * yv.sin() + 1.0 / xv)).abs() < 1e-15);
        assert!((out[1] - (2.0 * xv * yv.sin() - 1.0 / (xv * xv))).abs() < 1e-15);
        assert!((out[2] - (xv * xv * yv.cos())).abs() < 1e-15);
    }

    #[test]
    fn square_root_and_its_derivative() {
        // e = √(x² + 1) ; ∂e/∂x = x / √(x² + 1)
        let mut g = Graph::new();
        let x = g.var("x");
        let x2 = g.powi(x, 2);
        let one = g.one();
        let a = g.add(x2, one);
        let e = g.sqrt(a);
        let dx = diff(&mut g, e, 0);
        let tape = Tape::new(&g, &[e, dx]);
        let xv = 0.75_f64;
        let out = tape.eval(&[xv]);
        assert_eq!(out[0], 1.25);
        assert!((out[1] - 0.6).abs() < 1e-15);
        let four = g.constant(4.0);
        let two = g.sqrt(four);
        assert_eq!(g.as_const(two), Some(2.0), "constants fold");
    }

    #[test]
    fn structural_zero_derivatives_fold() {
        let mut g = Graph::new();
        let x = g.var("x");
        let _y = g.var("y");
        let e = g.cos(x);
        let dy = diff(&mut g, e, 1);
        assert!(g.is_zero(dy));
    }

    /// The partial tape of one variable re-evaluates only what depends on it, and gives the full
    /// tape's outputs bit for bit; outputs that do not depend on it are left alone.
    #[test]
    fn a_partial_tape_matches_the_full_one() {
        // Outputs: a = x² sin(y) + 1/x (depends on y), b = cos(x) · 3 (does not), c = √(y² + x).
        let mut g = Graph::new();
        let x = g.var("x");
        let y = g.var("y");
        let x2 = g.powi(x, 2);
        let sy = g.sin(y);
        let t = g.mul(x2, sy);
        let rx = g.recip(x);
        let a = g.add(t, rx);
        let cx = g.cos(x);
        let three = g.constant(3.0);
        let b = g.mul(cx, three);
        let y2 = g.powi(y, 2);
        let s = g.add(y2, x);
        let c = g.sqrt(s);
        let tape = Tape::new(&g, &[a, b, c]);
        let partial = tape.partial(&[1]);
        assert!(partial.depends(0) && !partial.depends(1) && partial.depends(2));
        // x², 1/x and x are read from the reference point (cos x is not needed).
        assert_eq!(partial.frontier_len(), 3);
        let (mut values, mut reference) = (Vec::new(), [0.0; 3]);
        tape.eval_values(&[1.7, -0.4], &mut values, &mut reference);
        assert_eq!(reference.to_vec(), tape.eval(&[1.7, -0.4]));
        let mut front = Vec::new();
        partial.gather(&values, &mut front);
        let mut scratch = Vec::new();
        for yv in [-0.4, 0.3, 2.5, -7.0] {
            let mut out = reference;
            partial.eval(&front, &[1.7, yv], &mut scratch, &mut out);
            let full = tape.eval(&[1.7, yv]);
            for i in 0..3 {
                assert_eq!(out[i].to_bits(), full[i].to_bits(), "output {i} at y = {yv}");
            }
        }
        let mut into = [0.0; 3];
        tape.eval_into(&[0.2, 0.9], &mut into);
        assert_eq!(into.to_vec(), tape.eval(&[0.2, 0.9]));
    }
}
