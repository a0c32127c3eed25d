//! Solver building blocks for uavgen-generated crates.
//!
//! This crate compiles and is tested on its own with a small example model
//! (`model.rs`, a damped oscillator) and example sizes (`dims.rs`). The
//! generator splices the source of `dims.rs`, `math.rs` and `rk4.rs` into every
//! generated crate: it replaces the values of the constants in `dims.rs` with
//! the model's sizes and options and supplies its own `model` module with the
//! same functions as `model.rs` here.
#![no_std]
#![forbid(unsafe_code)]
// `!(a > b)` is the NaN-safe comparison the factorisation needs.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

mod dims;
pub mod kernels;
pub mod math;
pub mod model;
pub mod mpc;
pub mod mpc_riccati;
pub mod qp;
pub mod riccati;
pub mod rk4;

pub use dims::*;
pub use model::{continuous_dynamics, continuous_jacobians};
pub use mpc::{Mpc, Solution, Status};
pub use rk4::discrete_linearization_into;
pub use rk4::{discrete_dynamics, discrete_jacobians, discrete_linearization};
