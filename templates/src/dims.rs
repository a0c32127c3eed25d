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
/// QP variables: the N·NU inputs of the horizon.
pub const NV: usize = N * NU;
/// Stage state weights diag(Q).
pub const Q: [Real; NX] = [1.0, 0.0];
/// Terminal state weights diag(Q_N).
pub const Q_TERMINAL: [Real; NX] = [1.0, 0.0];
/// Input weights diag(R).
pub const R: [Real; NU] = [0.1];
/// Input-rate weights diag(S) on uₖ − uₖ₋₁, u₋₁ = the input applied before stage 0 (both QP
/// solvers; docs/mpc.md).
pub const R_DELTA: [Real; NU] = [0.5];
/// Lower input bounds.
pub const U_MIN: [Real; NU] = [-1.0];
/// Upper input bounds.
pub const U_MAX: [Real; NU] = [1.0];
/// Pure delay of each input in seconds (the model's `corrections.latency`; zeros when it has
/// none). Not part of the dynamics: the runtime's delay compensator predicts over it.
pub const INPUT_DELAY: [Real; NU] = [0.0];
/// `INPUT_DELAY` rounded to whole samples of `DT`.
pub const INPUT_DELAY_SAMPLES: [usize; NU] = [0];
/// Lead of each channel over the delay every channel shares: dᵢ − minⱼ dⱼ samples
/// (dᵢ = `INPUT_DELAY_SAMPLES[i]`). The runtime's delay compensator predicts the state over the
/// shared delay; the solver treats the rest: channel i's inputs at stages k < `INPUT_LEAD[i]` were
/// sent already and are held fixed, and the input to send now on channel i is the plan's at stage
/// `INPUT_LEAD[i]` (docs/mpc.md, "Input delays").
pub const INPUT_LEAD: [usize; NU] = [0];
/// Hard cap on active-set iterations per QP.
pub const MAX_QP_ITERATIONS: usize = 200;
/// Work budget of one QP solve in multiply-adds (`max_qp_work`; default NV³, six full
/// factorisations of the condensed Hessian, at most 2³² − 1): the QP stops with `IterationCap` at a
/// feasible iterate rather than exceed it.
pub const MAX_QP_WORK: usize = NV * NV * NV;
/// Hard cap on interior-point iterations per QP of the stage-wise (Riccati) solver.
pub const MAX_IPM_ITERATIONS: usize = 30;
/// Trust region of the guess, |x̄ᵢ| ≤ TRUST_BOUND[i] (`Real::INFINITY`: none): twice the
/// generator's envelope on roll, pitch and the body rates. A guess that leaves it is replaced by
/// the rollout of its inputs in `prepare` (docs/mpc.md).
pub const TRUST_BOUND: [Real; NX] = [2.0, Real::INFINITY];
/// Plausibility envelope of x₀ and the reference, ENVELOPE_LO[i] ≤ xᵢ ≤ ENVELOPE_HI[i]
/// (`Real::NEG_INFINITY`, `Real::INFINITY`: none): the model file's `envelope` (the operating
/// envelope it was identified on, widened) where it declares one, else generic bounds far outside
/// the states the model was checked on (docs/mpc.md, "Plausibility"). A solve from beyond it
/// reports `Status::OutOfEnvelope` instead of `Solved`.
pub const ENVELOPE_LO: [Real; NX] = [-1.0e4, Real::NEG_INFINITY];
/// Upper end of the plausibility envelope (see `ENVELOPE_LO`).
pub const ENVELOPE_HI: [Real; NX] = [1.0e4, Real::INFINITY];
/// Largest error per state the QP is shown, as one ellipsoid over the states with a finite bound
/// (`Real::INFINITY`: none): ‖(r₀ᵢ − x̄₀ᵢ)/Bᵢ‖₂ ≤ 1, the reference window translated towards the
/// guess beyond it (`max_position_error` on x, y, z; docs/mpc.md, "Recovery").
pub const REFERENCE_ERROR_BOUND: [Real; NX] = [20.0, Real::INFINITY];
/// Growth of `REFERENCE_ERROR_BOUND` along the horizon, per second (`recovery_speed` /
/// `max_position_error`): beyond the bound the point the QP chases moves towards the reference at
/// `recovery_speed` (docs/mpc.md, "Recovery").
pub const REFERENCE_APPROACH_RATE: Real = 1.0;
/// States that are angles on the circle (yaw, by name): their errors are taken modulo 2π
/// (docs/mpc.md, "Angles on the circle").
pub const WRAPPED: [bool; NX] = [false, false];
/// Added to the diagonal of the condensed Hessian.
pub const REGULARISATION: Real = 1e-9;
/// Gain of the runtime's disturbance observer (`disturbance_gain`, 0 = off): each fresh
/// measurement moves the estimate e by this share of its one-sample prediction error
/// (docs/mpc.md, "Offset-free tracking").
pub const DISTURBANCE_GAIN: Real = 0.5;
/// Bound of each state's disturbance |eᵢ| per sample (x⁺ = F(x, u) + e): the
/// `disturbance_max_acceleration` times DT on vx, vy, vz; 0 where no disturbance is estimated.
pub const DISTURBANCE_BOUND: [Real; NX] = [0.0, 0.1];
