//! Symbolic core: hash-consed expression DAG, exact differentiation,
//! f64 evaluation and emission to Rust tokens.

pub mod diff;
pub mod emit;
pub mod eval;
pub mod expr;

pub use diff::{diff, jacobian};
pub use emit::{float_literal, Emitter, Float, NonFiniteConstant};
pub use eval::{Partial, Tape};
pub use expr::{Func, Graph, Id, Node};
