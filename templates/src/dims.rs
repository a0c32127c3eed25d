//! Sizes and options, fixed at generation time.

/// Floating-point type of every computation (`--float f32` makes it `f32`).
pub type Real = f64;
/// Number of states.
pub const NX: usize = 2;
/// Number of inputs.
pub const NU: usize = 1;
/// Columns of the sensitivity matrix S = ∂x/∂(x₀, u).
pub const NZ: usize = NX + NU;
/// Prediction horizon (samples).
pub const N: usize = 30;
/// Sample period in seconds.
pub const DT: Real = 0.1;
/// RK4 substeps per sample.
pub const SUBSTEPS: usize = 2;
