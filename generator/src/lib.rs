//! uavgen: from UAV model files to allocation-free `no_std` crates.
//!
//! Pipeline: [`model`] (parse + validate `uavgen-model/1`) → [`ir`] (symbolic
//! DAG of ẋ = f(x, u) with exact Jacobians, built on [`symbolic`]) →
//! [`discretize`] (RK4 substep choice) → [`codegen`] (one `TokenStream` per
//! module, spliced templates, prettyplease, atomic write).

pub mod analysis;
pub mod bench;
pub mod codegen;
pub mod commands;
pub mod diagnose;
pub mod discretize;
pub mod evaluate;
pub mod fuzzing;
pub mod identify;
pub mod import;
pub mod interrupt;
pub mod ir;
pub mod logs;
pub mod metrics;
pub mod model;
pub mod mpc_options;
pub mod reference;
pub mod selfcheck;
pub mod sim;
pub mod symbolic;
pub mod track;
pub mod validate;

pub use codegen::{generate, Float, GenerateOptions, GeneratedCrate};
pub use ir::ModelIr;
pub use model::{load, Model};
pub use mpc_options::MpcOptions;
pub use sim::{Plant, PlantError, PlantFile, Profile, SimulateOptions};
#[cfg(feature = "python")]
mod python;
