//! Exact symbolic differentiation on the DAG.
//!
//! `d/dv` is computed once per node (memoised), so the derivative of a DAG is
//! again a DAG of comparable size, and structural zeros fold away to the
//! constant 0 node, which the emitter skips.

use super::expr::{Func, Graph, Id, Node};
use std::collections::HashMap;

/// Memoised differentiation with respect to one variable.
pub struct Differentiator {
    var: u32,
    memo: HashMap<Id, Id>,
}

impl Differentiator {
    pub fn new(var: usize) -> Self {
        Self {
            var: var as u32,
            memo: HashMap::new(),
        }
    }

    /// ∂e/∂v
    pub fn diff(&mut self, g: &mut Graph, e: Id) -> Id {
        // Children have smaller ids: differentiate bottom-up without recursion.
        for id in g.reachable(&[e]) {
            if self.memo.contains_key(&id) {
                continue;
            }
            let d = self.rule(g, id);
            self.memo.insert(id, d);
        }
        self.memo[&e]
    }

    fn d(&self, id: Id) -> Id {
        self.memo[&id]
    }

    fn rule(&self, g: &mut Graph, id: Id) -> Id {
        match g.node(id) {
            Node::Const(_) => g.zero(),
            Node::Var(v) => {
                if v == self.var {
                    g.one()
                } else {
                    g.zero()
                }
            }
            // d(a + b) = da + db
            Node::Add(a, b) => g.add(self.d(a), self.d(b)),
            // d(a·b) = da·b + a·db
            Node::Mul(a, b) => {
                let l = g.mul(self.d(a), b);
                let r = g.mul(a, self.d(b));
                g.add(l, r)
            }
            // d(−a) = −da
            Node::Neg(a) => g.neg(self.d(a)),
            // d(1/a) = −da · (1/a)²
            Node::Recip(a) => {
                let da = self.d(a);
                if g.is_zero(da) {
                    return da;
                }
                let r2 = g.mul(id, id);
                let t = g.mul(da, r2);
                g.neg(t)
            }
            // d(aⁿ) = n aⁿ⁻¹ da
            Node::Powi(a, n) => {
                let da = self.d(a);
                if g.is_zero(da) {
                    return da;
                }
                let p = g.powi(a, n - 1);
                let c = g.constant(f64::from(n));
                let cp = g.mul(c, p);
                g.mul(cp, da)
            }
            // d sin a = cos a · da ; d cos a = −sin a · da ; d √a = da / (2 √a)
            Node::Call(func, a) => {
                let da = self.d(a);
                if g.is_zero(da) {
                    return da;
                }
                match func {
                    Func::Sin => {
                        let c = g.cos(a);
                        g.mul(c, da)
                    }
                    Func::Cos => {
                        let s = g.sin(a);
                        let t = g.mul(s, da);
                        g.neg(t)
                    }
                    Func::Sqrt => {
                        let half = g.constant(0.5);
                        let r = g.recip(id);
                        let t = g.mul(half, r);
                        g.mul(t, da)
                    }
                }
            }
        }
    }
}

/// ∂e/∂v for a single expression.
pub fn diff(g: &mut Graph, e: Id, var: usize) -> Id {
    Differentiator::new(var).diff(g, e)
}

/// Jacobian ∂outputs/∂vars as `jac[i][j] = ∂outputs[i]/∂var_j`.
pub fn jacobian(g: &mut Graph, outputs: &[Id], vars: &[usize]) -> Vec<Vec<Id>> {
    let mut jac = vec![Vec::with_capacity(vars.len()); outputs.len()];
    for &v in vars {
        let mut d = Differentiator::new(v);
        for (row, &e) in jac.iter_mut().zip(outputs) {
            row.push(d.diff(g, e));
        }
    }
    jac
}
