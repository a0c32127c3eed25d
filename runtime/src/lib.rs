//! Runtime for uavgen-generated model-predictive controllers on flight computers.
//!
//! `#![no_std]`, no allocation, no `unsafe`, no panicking paths in the control path. The pieces:
//!
//! - [`Real`]: the floating-point type of a generated crate (`f32` or `f64`), with the few
//!   functions the runtime needs (through `libm`);
//! - [`MpcSolver`]: the interface of a real-time-iteration MPC solver, generic over its sizes, and
//!   [`mpc_adapter!`], which implements it for the `Mpc` of a generated crate;
//! - [`reference`](mod@reference): reference windows for the horizon — the paper's built-in trajectories
//!   ([`Trajectory`]), a constant reference, a closure, and a time-stamped [`SetpointBuffer`];
//! - [`Controller`]: the RTI timeline (`feedback` → apply the input → `prepare_next`), input and
//!   output validation, and cycle-counter timings ([`CycleCounter`], [`Timings`]);
//! - [`DelayCompensator`](mod@delay): prediction over known input delays, so the MPC solves from
//!   the state at which its command takes effect (an option of the [`Controller`]).
//!
//! ```
//! use uavgen_runtime::{Controller, MpcSolver, Solution, Status, Trajectory};
//!
//! // A stand-in solver; with a generated crate, `mpc_adapter!(pub struct SindyMpc(sindy_m100));`
//! // defines one.
//! struct Hover;
//! impl MpcSolver<f64, 12, 4, 31> for Hover {
//!     const DT: f64 = 1.0 / 30.0;
//!     const U_MIN: [f64; 4] = [-5.0, -0.611, -0.611, -2.618];
//!     const U_MAX: [f64; 4] = [5.0, 0.611, 0.611, 2.618];
//!     fn initialize(&mut self, _x0: &[f64; 12], _u: &[f64; 4]) {}
//!     fn prepare(&mut self, _reference: &[[f64; 12]; 31]) -> Status {
//!         Status::Solved
//!     }
//!     fn feedback(&mut self, _x0: &[f64; 12]) -> Solution<f64, 4> {
//!         Solution { u0: [0.0; 4], status: Status::Solved, qp_iterations: 1, cost: 0.0 }
//!     }
//!     fn shift(&mut self) {}
//! }
//!
//! let mut controller = Controller::new(Hover, Trajectory::Circular);
//! controller.start(0.0).unwrap();
//! let x = [0.0; 12]; // the measured state
//! let u = match controller.feedback(&x) {
//!     Ok(solution) => solution.u0,
//!     Err(error) => error.solution.u0, // still finite and within the bounds
//! };
//! // ... apply u, then prepare the next sample while waiting for it:
//! controller.prepare_next().unwrap();
//! assert_eq!(u, [0.0; 4]);
//! ```
#![no_std]
#![forbid(unsafe_code)]
#![cfg_attr(
    not(test),
    deny(clippy::indexing_slicing, clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]
#![warn(missing_docs)]

pub mod controller;
pub mod delay;
pub mod disturbance;
mod real;
pub mod reference;
pub mod solver;

pub use controller::{
    ControlError, ControlErrorKind, Controller, CycleCounter, CycleStats, NoCycleCounter, Supervision,
    SupervisorReport, Timings,
};
pub use delay::{DelayCompensator, DelayTooLong, NoDelay, StatePredictor};
pub use disturbance::DisturbanceObserver;
pub use real::Real;
pub use reference::{
    ConstantReference, FnReference, Interpolation, ReferenceError, ReferenceSource, SetpointBuffer, SetpointError,
    Trajectory,
};
pub use solver::{MpcSolver, Solution, Status};

#[cfg(test)]
mod tests;
