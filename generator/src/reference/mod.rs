//! The generic reference MPC solver (std, f64, interpreted): the real-time
//! iteration of docs/mpc.md on a [`ModelIr`](crate::ModelIr), with the sparse
//! QP of each iteration solved by clarabel. Tests compare the generated
//! solver against it.
//!
//! - `linearize`: x⁺ = F(x, u) and (A, B) by RK4 with forward sensitivities
//!   ([`discrete_linearization`]);
//! - `mpc`: the solver, [`GenericMpc`].

pub mod linearize;
pub mod mpc;

pub use linearize::discrete_linearization;
pub use mpc::{clarabel_settings, GenericMpc, GenericSolution, MpcProblem, ReferenceError};
