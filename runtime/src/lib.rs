//! Runtime for uavgen-generated controllers on flight computers (`no_std`, no
//! allocation). This release defines the model interface that generated crates
//! satisfy; the controller wrapper arrives with the generated MPC.
#![no_std]
#![forbid(unsafe_code)]

/// The discrete-time model interface every generated crate exposes as free
/// functions; firmware code that is generic over models can wrap them in this
/// trait. `R` is the crate's `Real`.
pub trait DiscreteModel<R, const NX: usize, const NU: usize> {
    /// Sample period in seconds.
    const DT: R;
    /// x⁺ = F(x, u).
    fn step(x: &[R; NX], u: &[R; NU]) -> [R; NX];
    /// (A, B) = (∂F/∂x, ∂F/∂u).
    #[allow(clippy::type_complexity)]
    fn jacobians(x: &[R; NX], u: &[R; NU]) -> ([[R; NX]; NX], [[R; NU]; NX]);
}
