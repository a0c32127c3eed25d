//! Emission of expressions as straight-line Rust (`let` per shared node).
//!
//! The emitter walks the DAG in topological order and binds every non-leaf
//! node it needs to a fresh `tN` local exactly once, so the emitted code
//! inherits the graph's common-subexpression elimination. Constants and
//! variables are inlined. Math functions resolve to `sin`, `cos`, `sqrt` and `powi`
//! in scope at the call site (the spliced `math` module of the generated crate).

use super::expr::{Func, Graph, Id, Node};
use proc_macro2::{Ident, Literal, Span, TokenStream};
use quote::{format_ident, quote};
use std::collections::{BTreeSet, HashMap};

/// Emits `let` statements for expressions of one graph into one function body.
pub struct Emitter<'g> {
    g: &'g Graph,
    vars: Vec<TokenStream>,
    bound: HashMap<Id, TokenStream>,
    statements: Vec<TokenStream>,
    next: usize,
    prefix: String,
    float: Float,
    used_functions: BTreeSet<&'static str>,
    /// The first constant that had no literal (its place holds `0.0`; see [`Emitter::check`]).
    error: Option<NonFiniteConstant>,
}

/// Floating-point type of emitted code.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Float {
    #[default]
    F64,
    F32,
}

impl Float {
    pub fn name(self) -> &'static str {
        match self {
            Float::F64 => "f64",
            Float::F32 => "f32",
        }
    }
}

/// A constant that has no literal in the generated code's float type: NaN, infinite, or (for
/// f32) beyond f32's range. Model validation keeps every parameter far inside these limits, so
/// this is reached only through a constant folded from extreme values.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
#[error("the constant {} folded from the model has no {} literal (not finite); check the model's parameters against the ranges of docs/model-format.md#ranges", crate::validate::short(*.value), .float.name())]
pub struct NonFiniteConstant {
    pub value: f64,
    pub float: Float,
}

/// A float literal (unsuffixed, so it takes the type `Real` of its context),
/// written with the shortest digits that round-trip in `float`; an error for a value that is
/// not finite in `float`.
pub fn float_literal(value: f64, float: Float) -> Result<TokenStream, NonFiniteConstant> {
    let finite = match float {
        Float::F64 => value.is_finite(),
        Float::F32 => (value as f32).is_finite(),
    };
    if !finite {
        return Err(NonFiniteConstant { value, float });
    }
    let lit = match float {
        Float::F64 => Literal::f64_unsuffixed(value.abs()),
        Float::F32 => Literal::f32_unsuffixed(value.abs() as f32),
    };
    Ok(if value.is_sign_negative() {
        quote!(-#lit)
    } else {
        quote!(#lit)
    })
}

impl<'g> Emitter<'g> {
    /// `vars[i]` is the token expression for graph variable `i`.
    pub fn new(g: &'g Graph, vars: Vec<TokenStream>, float: Float) -> Self {
        assert_eq!(vars.len(), g.var_count(), "one token per variable");
        Self {
            g,
            vars,
            bound: HashMap::new(),
            statements: Vec::new(),
            next: 0,
            prefix: "t".into(),
            float,
            used_functions: BTreeSet::new(),
            error: None,
        }
    }

    /// Token expression (an atom: identifier, literal or variable) for `id`,
    /// emitting whatever `let` statements it needs first.
    pub fn atom(&mut self, id: Id) -> TokenStream {
        for node in self.g.reachable(&[id]) {
            if !self.bound.contains_key(&node) {
                let tokens = self.bind(node);
                self.bound.insert(node, tokens);
            }
        }
        self.bound[&id].clone()
    }

    /// Statements emitted so far (in order), leaving the emitter empty of them.
    pub fn take_statements(&mut self) -> Vec<TokenStream> {
        std::mem::take(&mut self.statements)
    }

    /// Names of the math functions (`sin`, `cos`, `sqrt`, `powi`) the statements call.
    /// `Err` if a constant had no literal: the emitted code is then wrong and must be dropped.
    pub fn check(&self) -> Result<(), NonFiniteConstant> {
        self.error.map_or(Ok(()), Err)
    }

    pub fn used_functions(&self) -> &BTreeSet<&'static str> {
        &self.used_functions
    }

    fn get(&self, id: Id) -> TokenStream {
        self.bound[&id].clone()
    }

    fn bind(&mut self, id: Id) -> TokenStream {
        let rhs = match self.g.node(id) {
            Node::Const(bits) => {
                return float_literal(f64::from_bits(bits), self.float).unwrap_or_else(|e| {
                    self.error.get_or_insert(e);
                    quote!(0.0)
                })
            }
            Node::Var(v) => return self.vars[v as usize].clone(),
            Node::Add(a, b) => {
                let (a, b) = (self.get(a), self.get(b));
                quote!(#a + #b)
            }
            Node::Mul(a, b) => {
                let (a, b) = (self.get(a), self.get(b));
                quote!(#a * #b)
            }
            Node::Neg(a) => {
                let a = self.get(a);
                quote!(-#a)
            }
            Node::Recip(a) => {
                let a = self.get(a);
                quote!(1.0 / #a)
            }
            Node::Powi(a, n) => {
                let a = self.get(a);
                let pos = match n.unsigned_abs() {
                    2 => quote!(#a * #a),
                    3 => quote!(#a * #a * #a),
                    k => {
                        let k = Literal::u32_unsuffixed(k);
                        self.used_functions.insert("powi");
                        quote!(powi(#a, #k))
                    }
                };
                if n < 0 {
                    quote!(1.0 / (#pos))
                } else {
                    pos
                }
            }
            Node::Call(func @ (Func::Sin | Func::Cos), a) => {
                let arg = self.get(a);
                let partner = match func {
                    Func::Sin => Func::Cos,
                    _ => Func::Sin,
                };
                // sin and cos of the same argument: both from one `sincos` (one argument
                // reduction; the same values as `sin` and `cos`).
                if let Some(other) = self
                    .g
                    .find(Node::Call(partner, a))
                    .filter(|o| !self.bound.contains_key(o))
                {
                    let s = format_ident!("{}{}", self.prefix, self.next);
                    let c = format_ident!("{}{}", self.prefix, self.next + 1);
                    self.next += 2;
                    self.used_functions.insert("sincos");
                    self.statements.push(quote!(let (#s, #c) = sincos(#arg);));
                    let (own, other_name) = match func {
                        Func::Sin => (s, c),
                        _ => (c, s),
                    };
                    self.bound.insert(other, quote!(#other_name));
                    return quote!(#own);
                }
                if matches!(func, Func::Sin) {
                    self.used_functions.insert("sin");
                    quote!(sin(#arg))
                } else {
                    self.used_functions.insert("cos");
                    quote!(cos(#arg))
                }
            }
            Node::Call(Func::Sqrt, a) => {
                let a = self.get(a);
                self.used_functions.insert("sqrt");
                quote!(sqrt(#a))
            }
        };
        let name = format_ident!("{}{}", self.prefix, self.next);
        self.next += 1;
        self.statements.push(quote!(let #name = #rhs;));
        quote!(#name)
    }
}

/// An identifier for a user-supplied variable name, or `fallback` when the
/// name cannot be a Rust local (keyword, invalid, or clashing with `reserved`).
pub fn local_ident(name: &str, fallback: &str, reserved: &[&str]) -> Ident {
    let clashes_with_temporary =
        name.len() > 1 && name.starts_with('t') && name[1..].chars().all(|c| c.is_ascii_digit());
    if !clashes_with_temporary && !reserved.contains(&name) && syn::parse_str::<Ident>(name).is_ok() {
        Ident::new(name, Span::call_site())
    } else {
        Ident::new(fallback, Span::call_site())
    }
}
