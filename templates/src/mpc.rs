//! Real-time-iteration MPC: one Gauss-Newton SQP step per sample on the
//! multiple-shooting NLP, condensed into a dense box QP in the N·NU inputs.
//! The algorithm and its notation are those of docs/mpc.md.

use crate::kernels;
use crate::math::sqrt;
use crate::qp::{BoxQp, QpResult, QpStatus};
use crate::rk4::{
    bound_disturbance, condition_reference, discrete_dynamics, discrete_linearization_into, hold_sent_inputs,
    input_to_send, is_sent, unwrap_measurement,
};
use crate::{
    Real, ENVELOPE_HI, ENVELOPE_LO, MAX_QP_ITERATIONS, MAX_QP_WORK, N, NU, NV, NX, Q, Q_TERMINAL, R, REGULARISATION,
    R_DELTA, TRUST_BOUND, U_MAX, U_MIN,
};

/// What happened in a solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    /// The QP was solved to optimality.
    Solved,
    /// The QP hit `MAX_QP_ITERATIONS` or `MAX_QP_WORK`; the best bounded iterate was applied.
    IterationCap,
    /// The condensed Hessian was not numerically positive definite; a multiple of I was added.
    HessianRegularised,
    /// Non-finite x₀ or reference: the previous plan is kept, u0 is its first input.
    InvalidInput,
    /// A non-finite value appeared in the linearisation or the step: the previous plan is kept.
    NumericalFailure,
    /// x₀ or the reference lies outside `ENVELOPE_LO`..`ENVELOPE_HI` (a broken estimator, a wrong unit): the step
    /// was taken as usual and u0 is finite and within bounds, but the model is extrapolated far
    /// beyond its data, so the input is not to be trusted.
    OutOfEnvelope,
}

/// Result of [`Mpc::feedback`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution {
    /// The input to apply now: finite and within [U_MIN, U_MAX] whatever the status.
    pub u0: [Real; NU],
    pub status: Status,
    /// Active-set iterations of the QP.
    pub qp_iterations: usize,
    /// ½ Σ (x̄ₖ − rₖ)ᵀ Qₖ (x̄ₖ − rₖ) + ½ Σ ūₖᵀ R ūₖ of the plan after this step.
    pub cost: Real,
}

/// `repr(u8)` with `Stale` first makes `Mpc::new()` all zero bits, so a static
/// solver lands in .bss instead of being copied from flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
enum Phase {
    /// No QP data for the current guess.
    Stale,
    /// prepare() succeeded; `regularised` if H needed δI.
    Prepared { regularised: bool },
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
    /// The rate term switched off (S = 0), only so that the template's tests can compare with the
    /// stage-wise solver, which has none. A flag rather than a copy of `R_DELTA`: `new()` must stay
    /// all zero bits, so that a `static` solver lives in .bss, not in flash-copied .data.
    rate_term_off: bool,
    reference: [[Real; NX]; N + 1],
    has_reference: bool,
    /// Aₖ = ∂F/∂x, Bₖ = ∂F/∂u at the guess; cₖ = F(x̄ₖ, ūₖ) − x̄ₖ₊₁.
    a: [[[Real; NX]; NX]; N],
    b: [[[Real; NU]; NX]; N],
    c: [[Real; NX]; N],
    /// Condensed Hessian (full symmetric storage).
    h: [[Real; NV]; NV],
    g: [Real; NV],
    lo: [Real; NV],
    hi: [Real; NV],
    v: [Real; NV],
    /// Free response / state step workspace.
    z: [[Real; NX]; N + 1],
    /// The condensing's chains (`condense`); after it, G = ∂g/∂x₀: `chains[k][r][i]` is
    /// ∂g_{i NU + r}/∂z₀ₖ = (Mᵢ Aᵢ ⋯ A₀)_{rk}.
    chains: kernels::Chains,
    /// The gradient at z₀ = x₀ − x̄₀ = 0 (`prepare`); `feedback` adds G z₀.
    g0: [Real; NV],
    qp: BoxQp<NV>,
    phase: Phase,
    /// The disturbance e of the prediction x̄ₖ₊₁ = F(x̄ₖ, ūₖ) + e (`set_disturbance`; 0 until set).
    disturbance: [Real; NX],
}

/// Component of each QP variable (stage k, input r: `kernels::INPUT_COMPONENT[r]`).
#[allow(clippy::modulo_one)] // NU = 1 in the template's example model
const QP_GROUPS: [u8; NV] = {
    let mut groups = [0u8; NV];
    let mut i = 0;
    while i < NV {
        groups[i] = kernels::INPUT_COMPONENT[i % NU];
        i += 1;
    }
    groups
};

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
            rate_term_off: false,
            reference: [[0.0; NX]; N + 1],
            has_reference: false,
            a: [[[0.0; NX]; NX]; N],
            b: [[[0.0; NU]; NX]; N],
            c: [[0.0; NX]; N],
            h: [[0.0; NV]; NV],
            g: [0.0; NV],
            lo: [0.0; NV],
            hi: [0.0; NV],
            v: [0.0; NV],
            z: [[0.0; NX]; N + 1],
            chains: [[[0.0; N]; NU]; NX],
            g0: [0.0; NV],
            qp: BoxQp::new(),
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

    /// Linearise along the guess, condense and factorise: all the work that
    /// does not need the measurement.
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
        self.condense();
        self.add_rate_hessian();
        self.gradient_at_the_guess();
        // lo = u_min − ū ≤ v ≤ u_max − ū = hi
        for k in 0..N {
            for i in 0..NU {
                self.lo[k * NU + i] = U_MIN[i] - self.us[k][i];
                self.hi[k * NU + i] = U_MAX[i] - self.us[k][i];
            }
        }
        match self.factorize() {
            Some(regularised) => {
                self.phase = Phase::Prepared { regularised };
                if regularised {
                    Status::HessianRegularised
                } else {
                    Status::Solved
                }
            }
            None => {
                self.phase = Phase::Failed;
                Status::NumericalFailure
            }
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

    /// Condensed Hessian by the backward recursion (the prediction matrix is never formed):
    /// P_N = Q_N, Mᵢ = Bᵢᵀ Pᵢ₊₁, H_ii = Mᵢ Bᵢ + R + δI, H_ij = Mᵢ Aᵢ Aᵢ₋₁ ⋯ A_{j+1} B_j (j < i),
    /// Pᵢ = Q + Aᵢᵀ Pᵢ₊₁ Aᵢ. Column block j of H is formed at once for every i > j: the chains
    /// Eᵢ = Mᵢ Aᵢ ⋯ A_{j+1} of all later stages are carried together and each multiplied by the same
    /// A_{j+1}, then by B_j (`kernels::chains_a`, `chains_b`; the same sums as E A and E B chain by
    /// chain).
    fn condense(&mut self) {
        let mut p = [[0.0; NX]; NX];
        for r in 0..NX {
            p[r][r] = Q_TERMINAL[r];
        }
        // The chains Eᵢ of every stage i > j side by side (`kernels::Chains`): Mᵢ Aᵢ ⋯ A_{j+2},
        // multiplied in place by A_{j+1}.
        let mut saved: kernels::SavedRows = [[0.0; N]; kernels::SAVED_ROWS];
        for j in (0..N).rev() {
            let bj = &self.b[j];
            if j + 1 < N {
                // Eᵢ ← Eᵢ A_{j+1} for i > j (Eⱼ₊₁ = Mⱼ₊₁ to start with)
                kernels::chains_a(&mut self.chains, &self.a[j + 1], j + 1, &mut saved);
            }
            // M = Bⱼᵀ P
            let m = kernels::bt_p(bj, &p);
            // H_jj = M Bⱼ + R + δI; an input sent already (column of Bⱼ zero) gets H_jj = 1 and
            // gradient 0 (`feedback`): decoupled, its step is 0.
            let mut hjj = kernels::e_b(&m, bj);
            for r in 0..NU {
                hjj[r][r] += if is_sent(j, r) { 1.0 } else { R[r] + REGULARISATION };
                self.h[j * NU + r][j * NU..(j + 1) * NU].copy_from_slice(&hjj[r]);
            }
            // H_ij = Eᵢ Bⱼ with Eᵢ = Mᵢ Aᵢ ⋯ A_{j+1} (i > j), and H_ji = H_ijᵀ
            kernels::chains_b(&self.chains, bj, j, j + 1, &mut self.h);
            // The chain of stage j starts at M.
            for k in 0..NX {
                for r in 0..NU {
                    self.chains[k][r][j] = m[r][k];
                }
            }
            if j > 0 {
                // Pⱼ = Q + Aⱼᵀ (P Aⱼ)
                p = kernels::at_p_a(&p, &self.a[j]);
                for r in 0..NX {
                    p[r][r] += Q[r];
                }
            }
        }
        // One step further, Eᵢ ← Eᵢ A₀ for every i: Gᵢ = Mᵢ Aᵢ ⋯ A₀ = Bᵢᵀ Pᵢ₊₁ Aᵢ ⋯ A₀ = ∂gᵢ/∂z₀
        // (z₀ moves every predicted state by Aₖ₋₁ ⋯ A₀ z₀, and Pᵢ₊₁ sums the weights of all of
        // them seen from stage i + 1), so that `feedback` forms g = g⁰ + G z₀ in NV·NX operations.
        kernels::chains_a(&mut self.chains, &self.a[0], 0, &mut saved);
    }

    /// g⁰: the condensed gradient at z₀ = 0 (the measurement equal to the guess's x̄₀), by the
    /// adjoint recursion on the free response z₀ = 0, zₖ₊₁ = Aₖ zₖ + cₖ:
    /// p_N = Q_N e_N, gⱼ = Bⱼᵀ pⱼ₊₁ + R ūⱼ + S (Δ̄ⱼ − Δ̄ⱼ₊₁), pⱼ = Q eⱼ + Aⱼᵀ pⱼ₊₁, eₖ = x̄ₖ + zₖ − rₖ.
    fn gradient_at_the_guess(&mut self) {
        self.z[0] = [0.0; NX];
        for k in 0..N {
            self.z[k + 1] = kernels::a_x_add(&self.a[k], &self.z[k], &self.c[k]);
        }
        let mut p = [0.0; NX];
        for i in 0..NX {
            p[i] = Q_TERMINAL[i] * (self.xs[N][i] + self.z[N][i] - self.reference[N][i]);
        }
        for j in (0..N).rev() {
            let mut ru = [0.0; NU];
            for r in 0..NU {
                // R ūⱼ + S (Δ̄ⱼ − Δ̄ⱼ₊₁): the input and rate terms' gradient at the guess.
                ru[r] = if is_sent(j, r) {
                    0.0
                } else {
                    let later = if j + 1 < N { self.rate(j + 1, r) } else { 0.0 };
                    R[r] * self.us[j][r] + self.rate_weight(r) * (self.rate(j, r) - later)
                };
            }
            let gj = kernels::bt_x_add(&self.b[j], &p, &ru);
            self.g0[j * NU..(j + 1) * NU].copy_from_slice(&gj);
            if j > 0 {
                let mut next = kernels::at_x(&self.a[j], &p);
                for i in 0..NX {
                    next[i] += Q[i] * (self.xs[j][i] + self.z[j][i] - self.reference[j][i]);
                }
                p = next;
            }
        }
    }

    /// The input-rate term ½ Σₖ Δₖᵀ S Δₖ, Δₖ = uₖ − uₖ₋₁ (u₋₁ fixed): S on the diagonal block of
    /// each uₖ once per rate it is part of (Δₖ and Δₖ₊₁), −S between uₖ₋₁ and uₖ. Inputs sent
    /// already are not variables (their step is 0): no term couples them.
    fn add_rate_hessian(&mut self) {
        for k in 0..N {
            for r in 0..NU {
                let s = self.rate_weight(r);
                if s == 0.0 || is_sent(k, r) {
                    continue;
                }
                let v = k * NU + r;
                self.h[v][v] += if k + 1 < N { 2.0 * s } else { s };
                if k > 0 && !is_sent(k - 1, r) {
                    self.h[v][v - NU] -= s;
                    self.h[v - NU][v] -= s;
                }
            }
        }
    }

    /// Without the rate term (S = 0): the stage-wise solver's problem, for the template's tests
    /// (`mpc_riccati.rs`, which a generated crate does not carry alongside this file).
    #[cfg(test)]
    #[allow(dead_code)]
    pub(crate) fn without_rate_term(mut self) -> Self {
        self.rate_term_off = true;
        self
    }

    /// diag(S)ᵣ: `R_DELTA[r]`, or 0 with the rate term off.
    #[inline]
    fn rate_weight(&self, r: usize) -> Real {
        if self.rate_term_off {
            0.0
        } else {
            R_DELTA[r]
        }
    }

    /// Δ̄ₖ,ᵣ = ūₖ,ᵣ − ūₖ₋₁,ᵣ of the guess (ū₋₁ = u₋₁).
    #[inline]
    fn rate(&self, k: usize, r: usize) -> Real {
        let before = if k == 0 { self.u_prev[r] } else { self.us[k - 1][r] };
        self.us[k][r] - before
    }

    /// Factorise H_FF for the warm-start working set; if a pivot fails, add
    /// δI with growing δ. Some(regularised) on success, None if hopeless.
    fn factorize(&mut self) -> Option<bool> {
        // The QP's components are set here, not in `new`, which stays all zero bits (.bss).
        self.qp.ensure_groups(&QP_GROUPS);
        if self.qp.factorize(&self.h).is_ok() {
            return Some(false);
        }
        if self.h.iter().enumerate().any(|(i, row)| !row[i].is_finite()) {
            return None;
        }
        self.factorize_regularised().then_some(true)
    }

    /// The box QP from v = 0 (ū is feasible, so 0 is in the box) with the current working set, at
    /// most `MAX_QP_ITERATIONS` iterations and `max_work` multiply-adds (docs/mpc.md).
    fn solve_qp(&mut self, max_work: usize) -> QpResult {
        self.v = [0.0; NV];
        self.qp.solve(
            &self.h,
            &self.g,
            &self.lo,
            &self.hi,
            &mut self.v,
            MAX_QP_ITERATIONS,
            max_work,
        )
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

    /// ½ Σₖ₌₀ᴺ (x̄ₖ − rₖ)ᵀ Qₖ (x̄ₖ − rₖ) + ½ Σ (ūₖᵀ R ūₖ + Δ̄ₖᵀ S Δ̄ₖ) of the guess (0 without a
    /// reference).
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
            for i in 0..NU {
                let d = self.rate(k, i);
                cost += 0.5 * (R[i] * self.us[k][i] * self.us[k][i] + self.rate_weight(i) * d * d);
            }
        }
        if cost.is_finite() {
            cost
        } else {
            Real::MAX
        }
    }

    /// Finish the step with the measurement x₀: gradient, QP, guess update. A step that would
    /// report success from an x₀ or reference outside `ENVELOPE_LO`..`ENVELOPE_HI` reports `OutOfEnvelope`.
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
        let regularised = match self.phase {
            Phase::Prepared { regularised } => regularised,
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
                    Status::Solved => false,
                    Status::HessianRegularised => true,
                    other => return self.feedback_after_failed_prepare(x0, other),
                }
            }
        };

        // g = g⁰ + G z₀ with z₀ = x₀ − x̄₀ (`prepare` formed g⁰ and G).
        for i in 0..NX {
            self.z[0][i] = x0[i] - self.xs[0][i];
        }
        self.g = self.g0;
        for k in 0..NX {
            let zk = self.z[0][k];
            for r in 0..NU {
                let column = &self.chains[k][r];
                for i in 0..N {
                    self.g[i * NU + r] += column[i] * zk;
                }
            }
        }

        // Box QP from v = 0 (ū is feasible, so 0 is in the box) with the warm-start working set.
        let mut result = self.solve_qp(MAX_QP_WORK);
        let mut regularised = regularised;
        if result.status == QpStatus::NotPositiveDefinite {
            // An append found H_FF not numerically positive definite: regularise and solve again.
            match self.factorize_regularised() {
                true => {
                    regularised = true;
                    // What the first solve spent is not spent again: MAX_QP_WORK bounds both.
                    let again = self.solve_qp(MAX_QP_WORK.saturating_sub(result.work));
                    result.iterations += again.iterations;
                    result.work += again.work;
                    result.status = again.status;
                }
                false => return self.keep_plan(Status::NumericalFailure),
            }
        }
        let status = match result.status {
            QpStatus::Optimal if regularised => Status::HessianRegularised,
            QpStatus::Optimal => Status::Solved,
            QpStatus::IterationCap => Status::IterationCap,
            QpStatus::NotPositiveDefinite => Status::HessianRegularised,
        };

        // Update the guess: δx₀ = z₀, δxₖ₊₁ = Aₖ δxₖ + Bₖ vₖ + cₖ; x̄ += δx, ū += v.
        let (xs_before, us_before) = (self.xs, self.us);
        self.xs[0] = *x0;
        let mut dx = self.z[0];
        for k in 0..N {
            let mut vk = [0.0; NU];
            vk.copy_from_slice(&self.v[k * NU..(k + 1) * NU]);
            // Inputs sent already stay as they were (their step is 0 up to rounding).
            for j in 0..NU {
                if is_sent(k, j) {
                    vk[j] = 0.0;
                }
            }
            let next = kernels::b_x_add(&self.b[k], &vk, &kernels::a_x_add(&self.a[k], &dx, &self.c[k]));
            let mut u = [0.0; NU];
            for j in 0..NU {
                u[j] = self.us[k][j] + vk[j];
            }
            self.us[k] = clamp_input(&u);
            for i in 0..NX {
                self.xs[k + 1][i] += next[i];
            }
            dx = next;
        }
        self.phase = Phase::Stale;
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

    /// Add δI (growing) until the current working set factorises; false if it never does.
    fn factorize_regularised(&mut self) -> bool {
        let mut scale: Real = 1.0;
        for i in 0..NV {
            scale = scale.max(self.h[i][i].abs());
        }
        let mut delta = sqrt(Real::EPSILON) * scale;
        for _ in 0..8 {
            for i in 0..NV {
                self.h[i][i] += delta;
            }
            if self.qp.factorize(&self.h).is_ok() {
                return true;
            }
            delta *= 100.0;
        }
        false
    }

    /// prepare + feedback.
    pub fn solve(&mut self, x0: &[Real; NX], reference: &[[Real; NX]; N + 1]) -> Solution {
        match self.prepare(reference) {
            Status::InvalidInput => self.keep_plan(Status::InvalidInput),
            _ => self.feedback(x0),
        }
    }

    /// Move the guess one sample ahead: x̄ₖ ← x̄ₖ₊₁, ūₖ ← ūₖ₊₁, the last input
    /// repeated and x̄_N ← F(x̄_{N−1}, ū_{N−1}); the stored reference and the
    /// QP working set shift alike.
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
        self.qp.shift_working_set(NU);
        self.phase = Phase::Stale;
    }
}

#[cfg(test)]
#[allow(clippy::modulo_one)] // NU = 1 in the template's example model
mod tests {
    use super::*;

    /// Dense reference: Γ (the prediction matrix, formed here only) and
    /// H = Γᵀ Q̄ Γ + R̄, to check the backward-recursion condensing.
    fn dense_hessian(mpc: &Mpc) -> [[Real; NV]; NV] {
        // Γ[k][j] = ∂δx_k/∂v_j, k = 1..N, as NX rows per k.
        let mut gamma = [[[0.0; NV]; NX]; N + 1];
        for k in 0..N {
            let (a, b) = (&mpc.a[k], &mpc.b[k]);
            for i in 0..NX {
                for col in 0..NV {
                    let mut s = 0.0;
                    for j in 0..NX {
                        s += a[i][j] * gamma[k][j][col];
                    }
                    if col / NU == k {
                        s += b[i][col % NU];
                    }
                    gamma[k + 1][i][col] = s;
                }
            }
        }
        let mut h = [[0.0; NV]; NV];
        for r in 0..NV {
            for c in 0..NV {
                let mut s = 0.0;
                for k in 1..=N {
                    let w = if k < N { &Q } else { &Q_TERMINAL };
                    for i in 0..NX {
                        s += gamma[k][i][r] * w[i] * gamma[k][i][c];
                    }
                }
                if r == c {
                    s += R[r % NU] + REGULARISATION;
                    // The rate term: S once per rate uₖ takes part in.
                    s += R_DELTA[r % NU] * if r / NU + 1 < N { 2.0 } else { 1.0 };
                }
                if r % NU == c % NU && (r / NU).abs_diff(c / NU) == 1 {
                    s -= R_DELTA[r % NU];
                }
                h[r][c] = s;
            }
        }
        h
    }

    fn reference(position: Real) -> [[Real; NX]; N + 1] {
        [[position, 0.0]; N + 1]
    }

    #[test]
    fn condensed_hessian_equals_dense_prediction_form() {
        let mut mpc = Mpc::new();
        mpc.initialize(&[0.3, -0.2], &[0.1]);
        assert_eq!(mpc.prepare(&reference(0.5)), Status::Solved);
        let dense = dense_hessian(&mpc);
        for r in 0..NV {
            for c in 0..NV {
                assert!(
                    (mpc.h[r][c] - dense[r][c]).abs() < 1e-12,
                    "H[{r}][{c}] = {} vs {}",
                    mpc.h[r][c],
                    dense[r][c]
                );
            }
        }
    }

    #[test]
    fn rti_on_a_linear_model_is_the_exact_mpc_solution() {
        // For a linear model one Gauss-Newton step is exact: a second step at the
        // same x₀ changes nothing.
        let mut mpc = Mpc::new();
        let x0 = [0.0, 0.0];
        let first = mpc.solve(&x0, &reference(0.5));
        assert_eq!(first.status, Status::Solved);
        let plan = *mpc.planned_inputs();
        let second = mpc.solve(&x0, &reference(0.5));
        assert_eq!(second.status, Status::Solved);
        // Up to the proximal term ½ δ ‖v‖² (δ = REGULARISATION), which shrinks each step by ~δ/λ(H).
        for k in 0..N {
            let d = (plan[k][0] - mpc.planned_inputs()[k][0]).abs();
            assert!(d < 1e-7, "stage {k}: second step moved the plan by {d:e}");
        }
        assert!((first.cost - second.cost).abs() < 1e-12);
        // The plan's predicted states are the model's trajectory (no defects left).
        let xs = mpc.predicted_states();
        for k in 0..N {
            let next = discrete_dynamics(&xs[k], &mpc.planned_inputs()[k]);
            assert!((next[0] - xs[k + 1][0]).abs() < 1e-12 && (next[1] - xs[k + 1][1]).abs() < 1e-12);
        }
    }

    #[test]
    fn a_disturbance_enters_every_predicted_state() {
        // With e set, the converged plan's states follow x̄ₖ₊₁ = F(x̄ₖ, ūₖ) + e (the model is linear:
        // the second RTI step is the exact solution).
        let mut mpc = Mpc::new();
        let e = [0.0, -0.02];
        assert!(mpc.set_disturbance(&e));
        assert!(!mpc.set_disturbance(&[Real::NAN, 0.0]), "a NaN is refused");
        assert_eq!(mpc.disturbance(), &e);
        // Beyond DISTURBANCE_BOUND ([0, 0.1] here) it is clamped.
        assert!(mpc.set_disturbance(&[1e300, -1e300]));
        assert_eq!(mpc.disturbance(), &[0.0, -0.1]);
        assert!(mpc.set_disturbance(&e));
        let x0 = [0.1, 0.0];
        mpc.solve(&x0, &reference(0.5));
        assert_eq!(mpc.solve(&x0, &reference(0.5)).status, Status::Solved);
        let xs = mpc.predicted_states();
        for k in 0..N {
            let next = discrete_dynamics(&xs[k], &mpc.planned_inputs()[k]);
            for i in 0..NX {
                assert!((next[i] + e[i] - xs[k + 1][i]).abs() < 1e-9, "stage {k}, state {i}");
            }
        }
        // shift extends the plan with the same prediction.
        mpc.shift();
        let xs = mpc.predicted_states();
        let last = discrete_dynamics(&xs[N - 1], &mpc.planned_inputs()[N - 1]);
        assert!((last[1] + e[1] - xs[N][1]).abs() < 1e-12);
    }

    #[test]
    fn with_the_plants_disturbance_the_plan_predicts_the_plant() {
        // The plant is the model plus a constant disturbance d. Told d, the MPC's one-step
        // prediction is the plant's next state; not told, it is off by d every sample.
        let d = [0.0, 0.03];
        for told in [true, false] {
            let mut mpc = Mpc::new();
            if told {
                mpc.set_disturbance(&d);
            }
            let mut x = [0.0, 0.0];
            let mut miss: Real = 0.0;
            for _ in 0..100 {
                let s = mpc.solve(&x, &reference(0.5));
                let predicted = mpc.predicted_states()[1];
                let plant = discrete_dynamics(&x, &s.u0);
                x = [plant[0] + d[0], plant[1] + d[1]];
                miss = (predicted[1] - x[1]).abs();
                mpc.shift();
            }
            if told {
                assert!(miss < 1e-9, "told: one-step miss {miss:e}");
            } else {
                assert!((miss - d[1]).abs() < 1e-6, "not told: one-step miss {miss:e}");
            }
        }
    }

    #[test]
    fn closed_loop_reaches_the_setpoint_within_bounds() {
        let mut mpc = Mpc::new();
        let mut x = [0.0, 0.0];
        for _ in 0..200 {
            let s = mpc.solve(&x, &reference(0.5));
            assert!(matches!(s.status, Status::Solved | Status::IterationCap));
            assert!(s.u0[0] >= U_MIN[0] && s.u0[0] <= U_MAX[0]);
            x = discrete_dynamics(&x, &s.u0);
            mpc.shift();
        }
        // At rest x₀ = B u / K; the optimal constant u balances ½ q (B u / K − 0.5)² against
        // ½ r u²: u = q (B/K) 0.5 / (q B²/K² + r) = 0.25 / 0.35, so x₀ = u / 2 ≈ 0.357 (the
        // finite horizon, the terminal weight and the rate term within the plan move it: 0.346).
        assert!((x[0] - 0.25 / 0.35 / 2.0).abs() < 0.015, "x = {x:?}");
        assert!(x[1].abs() < 1e-3);
    }

    #[test]
    fn saturating_reference_keeps_inputs_on_the_bound() {
        // A far setpoint saturates u at its upper bound (21 away; the QP sees 20 at stage 0,
        // REFERENCE_ERROR_BOUND, and 21 from stage 1).
        let mut mpc = Mpc::new();
        let s = mpc.solve(&[0.0, 0.0], &reference(21.0));
        assert_eq!(s.u0[0], U_MAX[0]);
        assert!(mpc
            .planned_inputs()
            .iter()
            .all(|u| u[0] <= U_MAX[0] && u[0] >= U_MIN[0]));
    }

    #[test]
    fn a_guess_outside_the_trust_region_is_rolled_out() {
        // x̄₅ beyond TRUST_BOUND[0]: prepare replaces the states by the rollout of the inputs.
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
            assert!(mpc.c[k].iter().all(|c| *c == 0.0));
        }
        // Inside the trust region the guess is kept (a multiple-shooting iterate with defects).
        xs[5][0] = 0.5 * TRUST_BOUND[0];
        assert!(mpc.set_guess(&xs, &us));
        assert_eq!(mpc.prepare(&reference(0.5)), Status::Solved);
        assert_eq!(*mpc.predicted_states(), xs);
        assert!(mpc.c[0].iter().any(|c| *c != 0.0));
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
