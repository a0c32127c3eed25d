//! Real-time-iteration MPC: one Gauss-Newton SQP step per sample on the
//! multiple-shooting NLP, its QP solved stage-wise (no condensing) by the
//! Riccati interior-point method of `riccati.rs` (`--qp riccati`). The public API
//! is that of the condensed solver (`mpc.rs`); the notation is docs/mpc.md's.

use crate::riccati::{IpmStatus, RiccatiIpm, StageQp};
use crate::rk4::{
    bound_disturbance, condition_reference, discrete_dynamics, discrete_linearization_into, hold_sent_inputs,
    input_to_send, is_sent, unwrap_measurement,
};
use crate::{
    Real, ENVELOPE_HI, ENVELOPE_LO, INPUT_LEAD, MAX_IPM_ITERATIONS, N, NU, NX, Q, Q_TERMINAL, R, R_DELTA, TRUST_BOUND,
    U_MAX, U_MIN,
};

/// What happened in a solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// The QP was solved to optimality.
    Solved,
    /// The QP hit `MAX_IPM_ITERATIONS`; the last iterate, clamped into the bounds, was applied.
    IterationCap,
    /// A pivot of a stage Hessian R + Σ + BᵀPB was not numerically positive and was raised.
    HessianRegularised,
    /// Non-finite x₀ or reference: the previous plan is kept, u0 is its first input.
    InvalidInput,
    /// A non-finite value appeared in the linearisation or the step: the previous plan is kept.
    NumericalFailure,
    /// x₀ or the reference lies outside `ENVELOPE_LO`..`ENVELOPE_HI` (a broken estimator, a wrong unit): the step
    /// was taken (u0 finite and within the bounds) but its plan means nothing (as in `mpc.rs`).
    OutOfEnvelope,
}

/// Result of [`Mpc::feedback`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    /// The input to apply now: finite and within [U_MIN, U_MAX] whatever the status.
    pub u0: [Real; NU],
    pub status: Status,
    /// Interior-point iterations of the QP.
    pub qp_iterations: usize,
    /// ½ Σ (x̄ₖ − rₖ)ᵀ Qₖ (x̄ₖ − rₖ) + ½ Σ (ūₖᵀ R ūₖ + Δ̄ₖᵀ S Δ̄ₖ) of the plan after this step.
    pub cost: Real,
}

/// `repr(u8)` with `Stale` first makes `Mpc::new()` all zero bits, so a static
/// solver lands in .bss instead of being copied from flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
enum Phase {
    /// No QP data for the current guess.
    Stale,
    /// prepare() succeeded.
    Prepared,
    /// prepare() rejected the reference.
    InvalidReference,
    /// prepare() met non-finite numbers.
    Failed,
}

/// The MPC solver with all its workspaces (no allocation, sizes fixed at compile time).
#[derive(Clone, Debug)]
pub struct Mpc {
    /// Guess x̄₀..x̄_N (a multiple-shooting iterate).
    xs: [[Real; NX]; N + 1],
    /// Guess ū₀..ū_{N−1}.
    us: [[Real; NU]; N],
    /// u₋₁: the input applied over the sample before stage 0 (where the rate term Δ₀ starts).
    u_prev: [Real; NU],
    reference: [[Real; NX]; N + 1],
    has_reference: bool,
    /// Aₖ = ∂F/∂x, Bₖ = ∂F/∂u at the guess; cₖ = F(x̄ₖ, ūₖ) − x̄ₖ₊₁.
    a: [[[Real; NX]; NX]; N],
    b: [[[Real; NU]; NX]; N],
    c: [[Real; NX]; N],
    /// eₖ = x̄ₖ − rₖ
    e: [[Real; NX]; N + 1],
    /// Box of the input step v: lo = u_min − ū ≤ v ≤ u_max − ū = hi.
    lo: [[Real; NU]; N],
    hi: [[Real; NU]; N],
    qp: RiccatiIpm,
    phase: Phase,
    /// The disturbance e of the prediction x̄ₖ₊₁ = F(x̄ₖ, ūₖ) + e (`set_disturbance`; 0 until set).
    disturbance: [Real; NX],
}

impl Default for Mpc {
    fn default() -> Self {
        Self::new()
    }
}

#[inline]
fn all_finite(values: &[Real]) -> bool {
    values.iter().all(|v| v.is_finite())
}

/// `ENVELOPE_LO[i]` ≤ xᵢ ≤ `ENVELOPE_HI[i]` for every state (false for a NaN).
fn within_envelope(x: &[Real; NX]) -> bool {
    x.iter()
        .zip(ENVELOPE_LO.iter().zip(&ENVELOPE_HI))
        .all(|(v, (lo, hi))| *v >= *lo && *v <= *hi)
}

/// |xᵢ| ≤ `TRUST_BOUND[i]` for every state (false for a NaN).
#[inline]
fn within_trust_region(x: &[Real; NX]) -> bool {
    x.iter().zip(&TRUST_BOUND).all(|(v, b)| v.abs() <= *b)
}

/// x projected onto the trust region, each state clipped to ±`TRUST_BOUND[i]`.
#[inline]
#[allow(clippy::manual_clamp)] // `clamp` would pass a NaN through; max/min map it to a bound
fn into_trust_region(x: &[Real; NX]) -> [Real; NX] {
    let mut out = *x;
    for (v, b) in out.iter_mut().zip(&TRUST_BOUND) {
        *v = v.max(-*b).min(*b);
    }
    out
}

#[inline]
#[allow(clippy::manual_clamp)] // `clamp` would pass a NaN through; max/min map it to a bound
fn clamp_input(u: &[Real; NU]) -> [Real; NU] {
    let mut out = [0.0; NU];
    for i in 0..NU {
        // A NaN becomes the bound nearest zero's side: max(NaN, lo) = lo.
        out[i] = u[i].max(U_MIN[i]).min(U_MAX[i]);
    }
    out
}

impl Mpc {
    /// A solver whose guess is all zeros.
    pub const fn new() -> Self {
        Self {
            xs: [[0.0; NX]; N + 1],
            us: [[0.0; NU]; N],
            u_prev: [0.0; NU],
            reference: [[0.0; NX]; N + 1],
            has_reference: false,
            a: [[[0.0; NX]; NX]; N],
            b: [[[0.0; NU]; NX]; N],
            c: [[0.0; NX]; N],
            e: [[0.0; NX]; N + 1],
            lo: [[0.0; NU]; N],
            hi: [[0.0; NU]; N],
            qp: RiccatiIpm::new(),
            phase: Phase::Stale,
            disturbance: [0.0; NX],
        }
    }

    /// Guess x̄ₖ = x0 for all k and ūₖ = u (clamped into the bounds); ignored if not finite.
    pub fn initialize(&mut self, x0: &[Real; NX], u: &[Real; NU]) {
        if !all_finite(x0) || !all_finite(u) {
            return;
        }
        let u = clamp_input(u);
        self.xs = [*x0; N + 1];
        self.us = [u; N];
        self.u_prev = u;
        self.phase = Phase::Stale;
    }

    /// Set the whole guess (e.g. from an external planner); inputs are clamped
    /// into the bounds. Returns false, changing nothing, if a value is not finite.
    pub fn set_guess(&mut self, xs: &[[Real; NX]; N + 1], us: &[[Real; NU]; N]) -> bool {
        if !xs.iter().all(|x| all_finite(x)) || !us.iter().all(|u| all_finite(u)) {
            return false;
        }
        self.xs = *xs;
        for k in 0..N {
            self.us[k] = clamp_input(&us[k]);
        }
        // u₋₁ (the input applied before the plan, set by `initialize` and `shift`) is not part of
        // the guess: it stays.
        self.phase = Phase::Stale;
        true
    }

    /// Predict with the disturbance e from the next `prepare` on: x̄ₖ₊₁ = F(x̄ₖ, ūₖ) + e at every
    /// stage (offset-free tracking: the runtime's `DisturbanceObserver` estimates e; docs/mpc.md).
    /// A constant e leaves Aₖ and Bₖ as they are and moves the defects only. Each eᵢ is clamped
    /// into ±`DISTURBANCE_BOUND[i]` (what the runtime's observer may estimate; 0 where it
    /// estimates none; `disturbance()` shows what is used). Returns false, changing nothing, if a
    /// value is not finite.
    pub fn set_disturbance(&mut self, e: &[Real; NX]) -> bool {
        if !all_finite(e) {
            return false;
        }
        self.disturbance = bound_disturbance(e);
        true
    }

    /// The disturbance e the prediction uses (`set_disturbance`).
    pub fn disturbance(&self) -> &[Real; NX] {
        &self.disturbance
    }

    /// Planned inputs ū₀..ū_{N−1} of the current guess.
    pub fn planned_inputs(&self) -> &[[Real; NU]; N] {
        &self.us
    }

    /// Predicted states x̄₀..x̄_N of the current guess.
    pub fn predicted_states(&self) -> &[[Real; NX]; N + 1] {
        &self.xs
    }

    /// Linearise along the guess and factorise the interior-point method's first Newton system
    /// (its start point does not depend on x₀): all the work that does not need the measurement.
    pub fn prepare(&mut self, reference: &[[Real; NX]; N + 1]) -> Status {
        if !reference.iter().all(|r| all_finite(r)) {
            self.phase = Phase::InvalidReference;
            return Status::InvalidInput;
        }
        self.reference = *reference;
        // Angles unwrapped next to x̄₀, the window translated to within REFERENCE_ERROR_BOUND of it.
        condition_reference(&mut self.reference, &self.xs[0]);
        self.has_reference = true;
        if !self.linearize() {
            self.phase = Phase::Failed;
            return Status::NumericalFailure;
        }
        for k in 0..=N {
            for i in 0..NX {
                self.e[k][i] = self.xs[k][i] - self.reference[k][i];
            }
        }
        // lo = u_min − ū ≤ v ≤ u_max − ū = hi
        for k in 0..N {
            for i in 0..NU {
                self.lo[k][i] = U_MIN[i] - self.us[k][i];
                self.hi[k][i] = U_MAX[i] - self.us[k][i];
            }
        }
        let qp = StageQp {
            a: &self.a,
            b: &self.b,
            c: &self.c,
            e: &self.e,
            us: &self.us,
            u_prev: &self.u_prev,
            s: &R_DELTA,
            lead: &INPUT_LEAD,
            lo: &self.lo,
            hi: &self.hi,
        };
        if self.qp.prepare(&qp) {
            self.phase = Phase::Prepared;
            Status::Solved
        } else {
            self.phase = Phase::Failed;
            Status::NumericalFailure
        }
    }

    /// (Fₖ, Aₖ, Bₖ) at the guess and the defects cₖ = Fₖ − x̄ₖ₊₁; false if anything is not finite.
    /// If a predicted state x̄₁..x̄_N has left the trust region (|x̄ᵢ| ≤ `TRUST_BOUND[i]`), the
    /// guess's states are first replaced by the rollout of its inputs from x̄₀, projected onto the
    /// trust region at every stage, x̄ₖ₊₁ = clip(Fₖ) (defects zero where nothing was clipped): at
    /// no extra cost, since Fₖ is computed here anyway. Unprojected, the rollout itself could run
    /// into the model's singularity (pd_m100: the 1-substep RK4 map from pitch 1.03 rad at a pitch
    /// rate of 5.5 rad/s reaches pitch 1.4 and then overflows to NaN).
    fn linearize(&mut self) -> bool {
        let rollout = !self.xs[1..].iter().all(within_trust_region);
        let mut finite = true;
        for k in 0..N {
            // Fₖ + e: the prediction of the stage (e = 0 unless `set_disturbance`).
            let mut next = discrete_linearization_into(&self.xs[k], &self.us[k], &mut self.a[k], &mut self.b[k]);
            for i in 0..NX {
                next[i] += self.disturbance[i];
            }
            if rollout {
                self.xs[k + 1] = into_trust_region(&next);
            }
            for i in 0..NX {
                self.c[k][i] = next[i] - self.xs[k + 1][i];
            }
            finite &= all_finite(&self.c[k])
                && self.a[k].iter().all(|r| all_finite(r))
                && self.b[k].iter().all(|r| all_finite(r));
            hold_sent_inputs(k, &mut self.b[k]);
        }
        finite
    }

    /// The previous plan: the input it sends now, nothing changed.
    fn keep_plan(&mut self, status: Status) -> Solution {
        Solution {
            u0: clamp_input(&input_to_send(&self.us)),
            status,
            qp_iterations: 0,
            cost: self.cost(),
        }
    }

    /// ½ Σₖ₌₀ᴺ (x̄ₖ − rₖ)ᵀ Qₖ (x̄ₖ − rₖ) + ½ Σ (ūₖᵀ R ūₖ + Δ̄ₖᵀ S Δ̄ₖ) of the guess, Δ̄ₖ = ūₖ − ūₖ₋₁
    /// (ū₋₁ = u₋₁; 0 without a reference).
    fn cost(&self) -> Real {
        if !self.has_reference {
            return 0.0;
        }
        let mut cost = 0.0;
        for k in 0..=N {
            let weights = if k < N { &Q } else { &Q_TERMINAL };
            for i in 0..NX {
                let e = self.xs[k][i] - self.reference[k][i];
                cost += 0.5 * weights[i] * e * e;
            }
        }
        for k in 0..N {
            let before = if k == 0 { &self.u_prev } else { &self.us[k - 1] };
            for i in 0..NU {
                let d = self.us[k][i] - before[i];
                cost += 0.5 * (R[i] * self.us[k][i] * self.us[k][i] + R_DELTA[i] * d * d);
            }
        }
        if cost.is_finite() {
            cost
        } else {
            Real::MAX
        }
    }

    /// Finish the step with the measurement x₀: the interior-point QP, guess update. A step that
    /// would report success from an x₀ or reference outside `ENVELOPE_LO`..`ENVELOPE_HI` reports `OutOfEnvelope`.
    pub fn feedback(&mut self, x0: &[Real; NX]) -> Solution {
        let mut solution = self.feedback_step(x0);
        let usable = matches!(
            solution.status,
            Status::Solved | Status::IterationCap | Status::HessianRegularised
        );
        if usable && !(within_envelope(x0) && self.reference.iter().all(within_envelope)) {
            solution.status = Status::OutOfEnvelope;
        }
        solution
    }

    fn feedback_step(&mut self, x0: &[Real; NX]) -> Solution {
        if !all_finite(x0) {
            return self.keep_plan(Status::InvalidInput);
        }
        // Angles moved by whole turns next to x̄₀: the heading the plan holds (docs/mpc.md).
        let x0 = &unwrap_measurement(x0, &self.xs[0]);
        match self.phase {
            Phase::Prepared => {}
            Phase::InvalidReference => return self.keep_plan(Status::InvalidInput),
            Phase::Failed => {
                // Restart from the measurement, holding the planned input.
                let u = self.us[0];
                self.initialize(x0, &u);
                return self.keep_plan(Status::NumericalFailure);
            }
            Phase::Stale => {
                if !self.has_reference {
                    return self.keep_plan(Status::InvalidInput);
                }
                let reference = self.reference;
                match self.prepare(&reference) {
                    Status::Solved => {}
                    other => return self.feedback_after_failed_prepare(x0, other),
                }
            }
        }
        // z₀ = x₀ − x̄₀
        let mut z0 = [0.0; NX];
        for i in 0..NX {
            z0[i] = x0[i] - self.xs[0][i];
        }
        let qp = StageQp {
            a: &self.a,
            b: &self.b,
            c: &self.c,
            e: &self.e,
            us: &self.us,
            u_prev: &self.u_prev,
            s: &R_DELTA,
            lead: &INPUT_LEAD,
            lo: &self.lo,
            hi: &self.hi,
        };
        let result = self.qp.solve(&qp, &z0, MAX_IPM_ITERATIONS);
        self.phase = Phase::Stale;
        let status = match result.status {
            IpmStatus::Optimal => Status::Solved,
            IpmStatus::IterationCap => Status::IterationCap,
            IpmStatus::Regularised => Status::HessianRegularised,
            IpmStatus::NumericalFailure => return self.keep_plan(Status::NumericalFailure),
        };

        // Update the guess: δx₀ = z₀, δxₖ₊₁ = Aₖ δxₖ + Bₖ vₖ + cₖ; x̄ += δx, ū += v (clamped).
        let (xs_before, us_before) = (self.xs, self.us);
        self.xs[0] = *x0;
        let mut dx = z0;
        for k in 0..N {
            let (a, b) = (&self.a[k], &self.b[k]);
            // Inputs sent already stay as they were: their column of Bₖ is zero and their rate is
            // not a decision, which decouples them in the QP, so the others' steps do not depend
            // on theirs.
            let mut v = self.qp.v[k];
            for j in 0..NU {
                if is_sent(k, j) {
                    v[j] = 0.0;
                }
            }
            let mut next = self.c[k];
            for i in 0..NX {
                for j in 0..NX {
                    next[i] += a[i][j] * dx[j];
                }
                for j in 0..NU {
                    next[i] += b[i][j] * v[j];
                }
            }
            let mut u = [0.0; NU];
            for j in 0..NU {
                u[j] = self.us[k][j] + v[j];
            }
            self.us[k] = clamp_input(&u);
            for i in 0..NX {
                self.xs[k + 1][i] += next[i];
            }
            dx = next;
        }
        if !self.xs.iter().all(|x| all_finite(x)) || !self.us.iter().all(|u| all_finite(u)) {
            self.xs = xs_before;
            self.us = us_before;
            return self.keep_plan(Status::NumericalFailure);
        }
        Solution {
            u0: input_to_send(&self.us),
            status,
            qp_iterations: result.iterations,
            cost: self.cost(),
        }
    }

    fn feedback_after_failed_prepare(&mut self, x0: &[Real; NX], status: Status) -> Solution {
        if status == Status::NumericalFailure {
            let u = self.us[0];
            self.initialize(x0, &u);
        }
        self.keep_plan(status)
    }

    /// prepare + feedback.
    pub fn solve(&mut self, x0: &[Real; NX], reference: &[[Real; NX]; N + 1]) -> Solution {
        match self.prepare(reference) {
            Status::InvalidInput => self.keep_plan(Status::InvalidInput),
            _ => self.feedback(x0),
        }
    }

    /// Move the guess one sample ahead: x̄ₖ ← x̄ₖ₊₁, ūₖ ← ūₖ₊₁, the last input
    /// repeated and x̄_N ← F(x̄_{N−1}, ū_{N−1}); the stored reference shifts alike.
    pub fn shift(&mut self) {
        // Stage 0's input is the one applied over the sample that now lies before the plan.
        self.u_prev = self.us[0];
        for k in 0..N {
            self.xs[k] = self.xs[k + 1];
            self.reference[k] = self.reference[k + 1];
        }
        for k in 0..N - 1 {
            self.us[k] = self.us[k + 1];
        }
        let mut last = discrete_dynamics(&self.xs[N - 1], &self.us[N - 1]);
        for i in 0..NX {
            last[i] += self.disturbance[i];
        }
        self.xs[N] = if all_finite(&last) { last } else { self.xs[N - 1] };
        self.phase = Phase::Stale;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reference(position: Real) -> [[Real; NX]; N + 1] {
        [[position, 0.0]; N + 1]
    }

    #[test]
    fn rti_on_a_linear_model_is_the_exact_mpc_solution() {
        let mut mpc = Mpc::new();
        let x0 = [0.0, 0.0];
        let first = mpc.solve(&x0, &reference(0.5));
        assert_eq!(first.status, Status::Solved);
        let plan = *mpc.planned_inputs();
        let second = mpc.solve(&x0, &reference(0.5));
        assert_eq!(second.status, Status::Solved);
        for k in 0..N {
            let d = (plan[k][0] - mpc.planned_inputs()[k][0]).abs();
            assert!(d < 1e-7, "stage {k}: second step moved the plan by {d:e}");
        }
        assert!((first.cost - second.cost).abs() < 1e-9);
        let xs = mpc.predicted_states();
        for k in 0..N {
            let next = discrete_dynamics(&xs[k], &mpc.planned_inputs()[k]);
            assert!((next[0] - xs[k + 1][0]).abs() < 1e-12 && (next[1] - xs[k + 1][1]).abs() < 1e-12);
        }
    }

    #[test]
    fn matches_the_condensed_solver_on_random_guesses() {
        // The same RTI step, input-rate term included (u₋₁ from `initialize`), by the condensed
        // active-set solver (mpc.rs) and by the Riccati interior-point method: plans agree to 1e-6
        // (the generated-vs-generic tolerance).
        let mut seed: u64 = 17;
        let mut next = move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as Real / (1u64 << 53) as Real * 2.0 - 1.0
        };
        let mut worst: Real = 0.0;
        for _ in 0..200 {
            let mut xs = [[0.0; NX]; N + 1];
            let mut us = [[0.0; NU]; N];
            for x in xs.iter_mut() {
                *x = [next(), next()];
            }
            for u in us.iter_mut() {
                *u = [1.2 * next()];
            }
            let x0 = [2.0 * next(), 2.0 * next()];
            let r = reference(3.0 * next());
            let u_prev = [1.2 * next()];
            let mut dense = crate::mpc::Mpc::new();
            let mut staged = Mpc::new();
            dense.initialize(&x0, &u_prev);
            staged.initialize(&x0, &u_prev);
            assert!(dense.set_guess(&xs, &us) && staged.set_guess(&xs, &us));
            let a = dense.solve(&x0, &r);
            let b = staged.solve(&x0, &r);
            assert_eq!(b.status, Status::Solved);
            assert_eq!(a.status, crate::mpc::Status::Solved);
            for k in 0..N {
                let d = (dense.planned_inputs()[k][0] - staged.planned_inputs()[k][0]).abs();
                worst = worst.max(d);
                assert!(d <= 1e-6, "stage {k}: {d:e}");
            }
            assert!((a.cost - b.cost).abs() <= 1e-6 * a.cost.abs().max(1.0));
        }
        assert!(worst <= 1e-6);
    }

    #[test]
    fn closed_loops_match_the_condensed_solver() {
        // 200 steps with shift (u₋₁ ← ū₀ each time) towards setpoints that saturate the input:
        // the rate term's u₋₁ moves with the plan, and both solvers send the same inputs.
        assert!(
            R_DELTA.iter().any(|&s| s != 0.0),
            "the template's example has a rate weight"
        );
        for target in [0.5, -3.0, 40.0] {
            let mut dense = crate::mpc::Mpc::new();
            let mut staged = Mpc::new();
            let (mut x, mut y) = ([0.3, -0.2], [0.3, -0.2]);
            let mut worst: Real = 0.0;
            for step in 0..200 {
                let a = dense.solve(&x, &reference(target));
                let b = staged.solve(&y, &reference(target));
                assert_eq!(a.status, crate::mpc::Status::Solved);
                assert_eq!(b.status, Status::Solved);
                let d = (a.u0[0] - b.u0[0]).abs();
                worst = worst.max(d);
                assert!(d <= 1e-6, "target {target}, step {step}: {} vs {}", a.u0[0], b.u0[0]);
                assert!((a.cost - b.cost).abs() <= 1e-6 * a.cost.abs().max(1.0), "step {step}");
                x = discrete_dynamics(&x, &a.u0);
                y = discrete_dynamics(&y, &b.u0);
                dense.shift();
                staged.shift();
            }
            assert!(worst <= 1e-6);
        }
    }

    #[test]
    fn closed_loop_reaches_the_setpoint_within_bounds() {
        let mut mpc = Mpc::new();
        let mut x = [0.0, 0.0];
        let mut max_iterations = 0;
        for _ in 0..200 {
            let s = mpc.solve(&x, &reference(0.5));
            assert_eq!(s.status, Status::Solved);
            max_iterations = max_iterations.max(s.qp_iterations);
            assert!(s.u0[0] >= U_MIN[0] && s.u0[0] <= U_MAX[0]);
            x = discrete_dynamics(&x, &s.u0);
            mpc.shift();
        }
        // Without the rate term the rest point is x₀ = 0.25 / 0.35 / 2 ≈ 0.357 (mpc.rs's test); the
        // finite horizon, the terminal weight and the rate term within the plan move it to 0.346
        // (the condensed solver's, to 1e-6: `closed_loops_match_the_condensed_solver`).
        assert!((x[0] - 0.346).abs() < 0.01, "x = {x:?}");
        assert!(x[1].abs() < 1e-3);
        assert!(max_iterations <= MAX_IPM_ITERATIONS);
    }

    #[test]
    fn saturating_reference_keeps_inputs_on_the_bound() {
        // 21 away: the QP sees 20 at stage 0 (REFERENCE_ERROR_BOUND) and 21 from stage 1.
        let mut mpc = Mpc::new();
        let s = mpc.solve(&[0.0, 0.0], &reference(21.0));
        assert_eq!(s.status, Status::Solved);
        assert_eq!(s.u0[0], U_MAX[0]);
        assert!(mpc
            .planned_inputs()
            .iter()
            .all(|u| u[0] <= U_MAX[0] && u[0] >= U_MIN[0]));
    }

    #[test]
    fn iteration_cap_applies_a_bounded_iterate() {
        let mut mpc = Mpc::new();
        assert_eq!(mpc.prepare(&reference(100.0)), Status::Solved);
        let z0 = [0.0; NX];
        let qp = StageQp {
            a: &mpc.a,
            b: &mpc.b,
            c: &mpc.c,
            e: &mpc.e,
            us: &mpc.us,
            u_prev: &mpc.u_prev,
            s: &R_DELTA,
            lead: &INPUT_LEAD,
            lo: &mpc.lo,
            hi: &mpc.hi,
        };
        let mut ipm = mpc.qp.clone();
        let r = ipm.solve(&qp, &z0, 1);
        assert_eq!(r.status, IpmStatus::IterationCap);
        let s = mpc.feedback(&[0.0, 0.0]);
        assert!(s.u0[0] >= U_MIN[0] && s.u0[0] <= U_MAX[0] && s.u0[0].is_finite());
    }

    #[test]
    fn a_guess_outside_the_trust_region_is_rolled_out() {
        let us = [[0.3]; N];
        let mut xs = [[0.1, -0.2]; N + 1];
        xs[5][0] = 2.0 * TRUST_BOUND[0];
        let mut mpc = Mpc::new();
        assert!(mpc.set_guess(&xs, &us));
        assert_eq!(mpc.prepare(&reference(0.5)), Status::Solved);
        let rolled = mpc.predicted_states();
        assert_eq!(rolled[0], xs[0]);
        for k in 0..N {
            assert_eq!(rolled[k + 1], discrete_dynamics(&rolled[k], &us[k]), "stage {k}");
        }
    }

    #[test]
    fn the_rollout_is_projected_onto_the_trust_region() {
        // From x₀ = 1.9 (bound 2) moving at 3 with full input, the oscillator's rollout leaves the
        // trust region within a step: each stage's state is clipped back to the bound, and the defect
        // is what was clipped (zero where nothing was).
        let us = [[U_MAX[0]]; N];
        let mut xs = [[1.9, 3.0]; N + 1];
        xs[N][0] = 2.0 * TRUST_BOUND[0];
        let mut mpc = Mpc::new();
        assert!(mpc.set_guess(&xs, &us));
        assert_eq!(mpc.prepare(&reference(0.5)), Status::Solved);
        let rolled = *mpc.predicted_states();
        let mut clipped = 0;
        for k in 0..N {
            let next = discrete_dynamics(&rolled[k], &us[k]);
            assert!(rolled[k + 1][0].abs() <= TRUST_BOUND[0], "stage {k}");
            assert_eq!(rolled[k + 1][1], next[1], "stage {k}");
            if next[0].abs() > TRUST_BOUND[0] {
                clipped += 1;
                assert_eq!(rolled[k + 1][0], TRUST_BOUND[0].copysign(next[0]), "stage {k}");
                assert_eq!(mpc.c[k][0], next[0] - rolled[k + 1][0], "stage {k}");
            } else {
                assert_eq!(rolled[k + 1][0], next[0], "stage {k}");
                assert_eq!(mpc.c[k][0], 0.0, "stage {k}");
            }
        }
        assert!(clipped > 0);
        assert!(mpc.feedback(&xs[0]).status == Status::Solved);
    }

    #[test]
    fn invalid_input_keeps_the_previous_plan() {
        let mut mpc = Mpc::new();
        let good = mpc.solve(&[0.0, 0.0], &reference(0.5));
        let plan = *mpc.planned_inputs();
        let s = mpc.feedback(&[Real::NAN, 0.0]);
        assert_eq!(s.status, Status::InvalidInput);
        assert_eq!(s.u0, plan[0]);
        assert_eq!(s.u0, good.u0);
        let mut bad_ref = reference(0.5);
        bad_ref[7][1] = Real::INFINITY;
        let s = mpc.solve(&[0.0, 0.0], &bad_ref);
        assert_eq!(s.status, Status::InvalidInput);
        assert_eq!(*mpc.planned_inputs(), plan);
        assert!(s.cost.is_finite());
    }
}
