//! Hash-consed expression DAG.
//!
//! Every node lives once in an arena ([`Graph`]); building a node that already
//! exists returns the existing [`Id`], so shared subexpressions are shared by
//! construction (common-subexpression elimination for free). Constructors fold
//! constants and apply the algebraic identities that keep derivatives small
//! (`0·a = 0`, `1·a = a`, `a + 0 = a`, …). Children always have smaller ids
//! than their parents, so the arena order is a topological order.

use std::collections::HashMap;

/// Index of a node in a [`Graph`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Id(pub(crate) u32);

impl Id {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// Unary functions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Func {
    Sin,
    Cos,
    /// √a (used by the quadratic-drag correction, always of a positive argument).
    Sqrt,
}

/// One node of the DAG. Constants are stored by bit pattern so they hash.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Node {
    Const(u64),
    Var(u32),
    Add(Id, Id),
    Mul(Id, Id),
    Neg(Id),
    /// Multiplicative inverse 1/a.
    Recip(Id),
    Powi(Id, i32),
    Call(Func, Id),
}

/// The arena of nodes with its hash-consing table.
#[derive(Default, Clone)]
pub struct Graph {
    nodes: Vec<Node>,
    lookup: HashMap<Node, Id>,
    var_names: Vec<String>,
}

impl Graph {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    pub fn node(&self, id: Id) -> Node {
        self.nodes[id.index()]
    }

    /// The node's id if the graph holds it already.
    pub fn find(&self, node: Node) -> Option<Id> {
        self.lookup.get(&node).copied()
    }

    pub fn var_count(&self) -> usize {
        self.var_names.len()
    }

    pub fn var_name(&self, index: usize) -> &str {
        &self.var_names[index]
    }

    fn intern(&mut self, node: Node) -> Id {
        if let Some(&id) = self.lookup.get(&node) {
            return id;
        }
        let id = Id(u32::try_from(self.nodes.len()).expect("expression graph too large"));
        self.nodes.push(node);
        self.lookup.insert(node, id);
        id
    }

    /// A new independent variable (index = creation order).
    pub fn var(&mut self, name: &str) -> Id {
        let index = self.var_names.len() as u32;
        self.var_names.push(name.to_owned());
        self.intern(Node::Var(index))
    }

    /// The node of variable number `index` (must exist).
    pub fn var_id(&mut self, index: usize) -> Id {
        assert!(index < self.var_names.len(), "variable {index} does not exist");
        self.intern(Node::Var(index as u32))
    }

    pub fn constant(&mut self, value: f64) -> Id {
        // Normalise −0 to +0 so both intern to the same node.
        let value = if value == 0.0 { 0.0 } else { value };
        self.intern(Node::Const(value.to_bits()))
    }

    pub fn as_const(&self, id: Id) -> Option<f64> {
        match self.node(id) {
            Node::Const(bits) => Some(f64::from_bits(bits)),
            _ => None,
        }
    }

    pub fn is_zero(&self, id: Id) -> bool {
        self.as_const(id) == Some(0.0)
    }

    pub fn is_one(&self, id: Id) -> bool {
        self.as_const(id) == Some(1.0)
    }

    pub fn zero(&mut self) -> Id {
        self.constant(0.0)
    }

    pub fn one(&mut self) -> Id {
        self.constant(1.0)
    }

    /// a + b
    pub fn add(&mut self, a: Id, b: Id) -> Id {
        match (self.as_const(a), self.as_const(b)) {
            (Some(x), Some(y)) => return self.constant(x + y),
            (Some(0.0), _) => return b,
            (_, Some(0.0)) => return a,
            _ => {}
        }
        // Commutative: order operands so a + b and b + a share a node.
        let (a, b) = if a <= b { (a, b) } else { (b, a) };
        self.intern(Node::Add(a, b))
    }

    /// a − b
    pub fn sub(&mut self, a: Id, b: Id) -> Id {
        let nb = self.neg(b);
        self.add(a, nb)
    }

    /// a · b
    pub fn mul(&mut self, a: Id, b: Id) -> Id {
        match (self.as_const(a), self.as_const(b)) {
            (Some(x), Some(y)) => return self.constant(x * y),
            (Some(0.0), _) => return a,
            (_, Some(0.0)) => return b,
            (Some(1.0), _) => return b,
            (_, Some(1.0)) => return a,
            (Some(-1.0), _) => return self.neg(b),
            (_, Some(-1.0)) => return self.neg(a),
            _ => {}
        }
        // c·(c'·y) = (c c')·y: keep one constant factor per product.
        if let Some((c, other)) = self.const_and_other(a, b) {
            if let Node::Mul(p, q) = self.node(other) {
                if let Some((c2, y)) = self.const_and_other(p, q) {
                    let cc = self.constant(c * c2);
                    return self.mul(cc, y);
                }
            }
        }
        let (a, b) = if a <= b { (a, b) } else { (b, a) };
        self.intern(Node::Mul(a, b))
    }

    /// (c, other) when exactly one of a, b is a constant c.
    fn const_and_other(&self, a: Id, b: Id) -> Option<(f64, Id)> {
        match (self.as_const(a), self.as_const(b)) {
            (Some(c), None) => Some((c, b)),
            (None, Some(c)) => Some((c, a)),
            _ => None,
        }
    }

    /// −a
    pub fn neg(&mut self, a: Id) -> Id {
        match self.node(a) {
            Node::Const(bits) => self.constant(-f64::from_bits(bits)),
            Node::Neg(inner) => inner,
            _ => self.intern(Node::Neg(a)),
        }
    }

    /// 1 / a
    pub fn recip(&mut self, a: Id) -> Id {
        match self.node(a) {
            Node::Const(bits) => self.constant(1.0 / f64::from_bits(bits)),
            Node::Recip(inner) => inner,
            _ => self.intern(Node::Recip(a)),
        }
    }

    /// a / b
    pub fn div(&mut self, a: Id, b: Id) -> Id {
        if self.is_zero(a) {
            return a;
        }
        let rb = self.recip(b);
        self.mul(a, rb)
    }

    /// aⁿ for integer n
    pub fn powi(&mut self, a: Id, n: i32) -> Id {
        match n {
            0 => return self.one(),
            1 => return a,
            -1 => return self.recip(a),
            _ => {}
        }
        if let Some(x) = self.as_const(a) {
            return self.constant(x.powi(n));
        }
        self.intern(Node::Powi(a, n))
    }

    pub fn sin(&mut self, a: Id) -> Id {
        if let Some(x) = self.as_const(a) {
            return self.constant(x.sin());
        }
        self.intern(Node::Call(Func::Sin, a))
    }

    pub fn cos(&mut self, a: Id) -> Id {
        if let Some(x) = self.as_const(a) {
            return self.constant(x.cos());
        }
        self.intern(Node::Call(Func::Cos, a))
    }

    /// √a
    pub fn sqrt(&mut self, a: Id) -> Id {
        if let Some(x) = self.as_const(a) {
            return self.constant(x.sqrt());
        }
        self.intern(Node::Call(Func::Sqrt, a))
    }

    /// Σ terms (empty sum = 0)
    pub fn sum(&mut self, terms: impl IntoIterator<Item = Id>) -> Id {
        let mut acc = self.zero();
        for t in terms {
            acc = self.add(acc, t);
        }
        acc
    }

    /// Π factors (empty product = 1)
    pub fn product(&mut self, factors: impl IntoIterator<Item = Id>) -> Id {
        let mut acc = self.one();
        for f in factors {
            acc = self.mul(acc, f);
        }
        acc
    }

    /// Nodes reachable from `roots`, in topological (arena) order.
    pub fn reachable(&self, roots: &[Id]) -> Vec<Id> {
        let mut mark = vec![false; self.nodes.len()];
        let mut stack: Vec<Id> = roots.to_vec();
        while let Some(id) = stack.pop() {
            if std::mem::replace(&mut mark[id.index()], true) {
                continue;
            }
            match self.node(id) {
                Node::Const(_) | Node::Var(_) => {}
                Node::Add(a, b) | Node::Mul(a, b) => {
                    stack.push(a);
                    stack.push(b);
                }
                Node::Neg(a) | Node::Recip(a) | Node::Powi(a, _) | Node::Call(_, a) => stack.push(a),
            }
        }
        mark.iter()
            .enumerate()
            .filter(|(_, &m)| m)
            .map(|(i, _)| Id(i as u32))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_consing_shares_nodes() {
        let mut g = Graph::new();
        let x = g.var("x");
        let y = g.var("y");
        let a = g.mul(x, y);
        let b = g.mul(y, x);
        assert_eq!(a, b, "commuted product is the same node");
        let s1 = g.sin(a);
        let s2 = g.sin(b);
        assert_eq!(s1, s2);
    }

    #[test]
    fn constant_folding_and_identities() {
        let mut g = Graph::new();
        let x = g.var("x");
        let two = g.constant(2.0);
        let three = g.constant(3.0);
        let six = g.mul(two, three);
        assert_eq!(g.as_const(six), Some(6.0));
        let zero = g.zero();
        let one = g.one();
        assert_eq!(g.mul(x, zero), zero);
        assert_eq!(g.mul(one, x), x);
        assert_eq!(g.add(x, zero), x);
        let nx = g.neg(x);
        assert_eq!(g.neg(nx), x);
        let two_x = g.mul(two, x);
        let six_x = g.mul(three, two_x);
        assert_eq!(six_x, g.mul(x, six), "constant factors merge");
        assert_eq!(g.powi(x, 1), x);
        let eight = g.powi(two, 3);
        assert_eq!(g.as_const(eight), Some(8.0));
        let neg_zero = g.constant(-0.0);
        assert_eq!(neg_zero, zero);
    }

    #[test]
    fn reachable_is_topological() {
        let mut g = Graph::new();
        let x = g.var("x");
        let s = g.sin(x);
        let p = g.mul(s, x);
        let _unused = g.cos(x);
        let order = g.reachable(&[p]);
        assert_eq!(order, vec![x, s, p]);
    }
}
