//! Explicit RK4 with `SUBSTEPS` substeps per sample and forward sensitivities.

use crate::math::sqrt;
use crate::model::{
    continuous_derivatives, continuous_dynamics, sensitivity_stage1, sensitivity_stage1_at_identity,
    sensitivity_stage2, sensitivity_stage2_at_identity, sensitivity_stage3, sensitivity_stage3_at_identity,
    sensitivity_stage4, sensitivity_stage4_at_identity, NJ,
};
use crate::{
    Real, DISTURBANCE_BOUND, DT, ENVELOPE_HI, ENVELOPE_LO, INPUT_LEAD, N, NU, NX, NZ, REFERENCE_APPROACH_RATE,
    REFERENCE_ERROR_BOUND, SUBSTEPS, WRAPPED,
};

/// Substep length h = DT / M.
pub const H: Real = DT / SUBSTEPS as Real;

/// y = x + a k
#[inline]
fn axpy(x: &[Real; NX], a: Real, k: &[Real; NX]) -> [Real; NX] {
    let mut y = *x;
    for (yi, ki) in y.iter_mut().zip(k) {
        *yi += a * ki;
    }
    y
}

/// One RK4 substep:
/// k1 = f(x), k2 = f(x + h/2 k1), k3 = f(x + h/2 k2), k4 = f(x + h k3),
/// x⁺ = x + h/6 (k1 + 2k2 + 2k3 + k4).
#[inline]
fn substep(x: &[Real; NX], u: &[Real; NU]) -> [Real; NX] {
    let k1 = continuous_dynamics(x, u);
    let k2 = continuous_dynamics(&axpy(x, 0.5 * H, &k1), u);
    let k3 = continuous_dynamics(&axpy(x, 0.5 * H, &k2), u);
    let k4 = continuous_dynamics(&axpy(x, H, &k3), u);
    let mut next = *x;
    for i in 0..NX {
        next[i] += H / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    next
}

/// x⁺ = F(x, u): the state one sample (DT) later, input held constant.
pub fn discrete_dynamics(x: &[Real; NX], u: &[Real; NU]) -> [Real; NX] {
    let mut xk = *x;
    for _ in 0..SUBSTEPS {
        xk = substep(&xk, u);
    }
    xk
}

/// (x⁺, A, B) with A[i][j] = ∂x⁺ᵢ/∂xⱼ and B[i][j] = ∂x⁺ᵢ/∂uⱼ, by forward
/// sensitivities through every stage: with S = ∂x/∂(x₀, u), starting at [I 0],
/// dkᵢ = ∂f/∂x · Sᵢ + ∂f/∂u · [0 I] and S⁺ = S + h/6 (dk1 + 2dk2 + 2dk3 + dk4).
/// This is the exact derivative of [`discrete_dynamics`].
#[allow(clippy::type_complexity)]
pub fn discrete_linearization(x: &[Real; NX], u: &[Real; NU]) -> ([Real; NX], [[Real; NX]; NX], [[Real; NU]; NX]) {
    let mut a = [[0.0; NX]; NX];
    let mut b = [[0.0; NU]; NX];
    let next = discrete_linearization_into(x, u, &mut a, &mut b);
    (next, a, b)
}

/// [`discrete_linearization`] writing A and B in place (the solvers' stage matrices, no copies):
/// returns x⁺.
///
/// The four stages of a substep go through the model's stage kernels (docs/discretisation.md): each
/// evaluates D = ∂f/∂x · Y + ∂f/∂u · [0 I] at its Y and combines it in place, ACC = D1 + 2 D2 + 2 D3
/// accumulated and the next stage's Y = S + a D written into one of two buffers, so no D is stored
/// and no matrix is copied. The first substep starts at S = [I 0] and uses the kernels specialised
/// to it. The sums are those of [`discrete_linearization`]'s recursion term for term.
pub fn discrete_linearization_into(
    x: &[Real; NX],
    u: &[Real; NU],
    a: &mut [[Real; NX]; NX],
    b: &mut [[Real; NU]; NX],
) -> [Real; NX] {
    let mut xk = *x;
    let mut s = [[0.0; NZ]; NX];
    for (i, row) in s.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    let mut acc = [[0.0; NZ]; NX];
    let mut y = [[0.0; NZ]; NX];
    let mut y_next = [[0.0; NZ]; NX];
    let mut jv = [0.0; NJ];
    for step in 0..SUBSTEPS {
        let first = step == 0;
        let k1 = continuous_derivatives(&xk, u, &mut jv);
        if first {
            sensitivity_stage1_at_identity(&jv, 0.5 * H, &mut acc, &mut y);
        } else {
            sensitivity_stage1(&jv, &s, 0.5 * H, &mut acc, &mut y);
        }
        let k2 = continuous_derivatives(&axpy(&xk, 0.5 * H, &k1), u, &mut jv);
        if first {
            sensitivity_stage2_at_identity(&jv, &y, 0.5 * H, &mut acc, &mut y_next);
        } else {
            sensitivity_stage2(&jv, &y, &s, 0.5 * H, &mut acc, &mut y_next);
        }
        let k3 = continuous_derivatives(&axpy(&xk, 0.5 * H, &k2), u, &mut jv);
        if first {
            sensitivity_stage3_at_identity(&jv, &y_next, H, &mut acc, &mut y);
        } else {
            sensitivity_stage3(&jv, &y_next, &s, H, &mut acc, &mut y);
        }
        let k4 = continuous_derivatives(&axpy(&xk, H, &k3), u, &mut jv);
        if first {
            sensitivity_stage4_at_identity(&jv, &y, H / 6.0, &acc, &mut s);
        } else {
            sensitivity_stage4(&jv, &y, H / 6.0, &acc, &mut s);
        }
        for i in 0..NX {
            xk[i] += H / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
    for i in 0..NX {
        a[i].copy_from_slice(&s[i][..NX]);
        b[i].copy_from_slice(&s[i][NX..]);
    }
    xk
}

/// (A, B) of [`discrete_linearization`].
#[allow(clippy::type_complexity)]
pub fn discrete_jacobians(x: &[Real; NX], u: &[Real; NU]) -> ([[Real; NX]; NX], [[Real; NU]; NX]) {
    let (_, a, b) = discrete_linearization(x, u);
    (a, b)
}

/// Whether input i at stage k of the plan was sent already: k < `INPUT_LEAD[i]` (its delay beyond
/// the one every channel shares; docs/mpc.md "Input delays"). Such an input is held, not a decision.
#[inline]
pub fn is_sent(k: usize, i: usize) -> bool {
    k < INPUT_LEAD[i]
}

/// Zero the columns of Bₖ of the inputs sent already at stage k: a step in them changes nothing,
/// so the QP sees them decoupled and the solver holds them.
#[inline]
pub fn hold_sent_inputs(k: usize, b: &mut [[Real; NU]; NX]) {
    for i in 0..NU {
        if is_sent(k, i) {
            for row in b.iter_mut() {
                row[i] = 0.0;
            }
        }
    }
}

/// The input to send now: channel i's planned input at stage `INPUT_LEAD[i]` (stage 0 without
/// delays or with equal ones).
#[inline]
pub fn input_to_send(us: &[[Real; NU]; N]) -> [Real; NU] {
    let mut u = [0.0; NU];
    for i in 0..NU {
        // INPUT_LEAD < N is checked at generation; min keeps the index in range regardless.
        u[i] = us[INPUT_LEAD[i].min(N - 1)][i];
    }
    u
}

/// e with each eᵢ clamped into ±`DISTURBANCE_BOUND[i]` (a NaN becomes 0 or a bound).
#[inline]
#[allow(clippy::manual_clamp)] // `clamp` would pass a NaN through; max/min map it to a bound
pub fn bound_disturbance(e: &[Real; NX]) -> [Real; NX] {
    let mut out = *e;
    for i in 0..NX {
        out[i] = e[i].max(-DISTURBANCE_BOUND[i]).min(DISTURBANCE_BOUND[i]);
    }
    out
}

/// 2π in `Real`.
const TAU: Real = core::f64::consts::TAU as Real;

/// d − 2π·m for the whole m that puts it in [−π, π] (up to rounding at the ends). Finite for every
/// finite d; far beyond the envelope (|d| ≳ 2⁶³·2π) the result means nothing, which
/// `OutOfEnvelope` reports.
#[inline]
pub fn wrap_angle(d: Real) -> Real {
    // `as` saturates and maps NaN to 0: no panic, no UB.
    let turns = (d / TAU) as i64;
    let mut w = d - TAU * turns as Real;
    if w > 0.5 * TAU {
        w -= TAU;
    } else if w < -0.5 * TAU {
        w += TAU;
    }
    w
}

/// The measurement x₀ with each angle on the circle (`WRAPPED`) moved by whole turns next to the
/// guess's x̄₀: an estimator's yaw wrapped to (−π, π] and the solver's unwrapped one are the same
/// heading (docs/mpc.md, "Angles on the circle").
#[inline]
pub fn unwrap_measurement(x0: &[Real; NX], guess: &[Real; NX]) -> [Real; NX] {
    let mut out = *x0;
    for i in 0..NX {
        if WRAPPED[i] {
            out[i] = guess[i] + wrap_angle(x0[i] - guess[i]);
        }
    }
    out
}

/// The reference window the QP tracks, conditioned in place against the guess's x̄₀
/// (docs/mpc.md, "Recovery" and "Angles on the circle"):
///
/// - each angle on the circle (`WRAPPED`) is unwrapped along the window, starting within π of
///   x̄₀ (the heading error is taken on the circle: a reference 2π away is the same heading);
/// - if the error of the states with a finite `REFERENCE_ERROR_BOUND` at stage 0,
///   ‖(r₀ᵢ − x̄₀ᵢ)/Bᵢ‖₂, exceeds 1, the whole window is translated in those states towards x̄₀
///   until it is 1: far from the reference the QP chases a point at the bound's distance, moving
///   with the reference, rather than the reference itself (the 1 s horizon without a velocity
///   weight otherwise flies the aircraft past it at full tilt into an orbit behind it). Within the
///   bound the window is unchanged.
///
/// Idempotent: conditioning a conditioned window against the same x̄₀ changes nothing. A window
/// with a value outside `ENVELOPE_LO`..`ENVELOPE_HI` is left as it is (`OutOfEnvelope`).
pub fn condition_reference(reference: &mut [[Real; NX]; N + 1], guess: &[Real; NX]) {
    // A window outside the plausibility envelope is left as it is: `feedback` reports it
    // (`OutOfEnvelope`), which an unwrapped or translated copy would hide.
    let plausible = reference.iter().all(|row| {
        row.iter()
            .zip(ENVELOPE_LO.iter().zip(&ENVELOPE_HI))
            .all(|(v, (lo, hi))| *v >= *lo && *v <= *hi)
    });
    if !plausible {
        return;
    }
    for i in 0..NX {
        if WRAPPED[i] {
            let mut previous = guess[i];
            for row in reference.iter_mut() {
                row[i] = previous + wrap_angle(row[i] - previous);
                previous = row[i];
            }
        }
    }
    let reference0 = reference[0];
    let mut excess: Real = 0.0;
    for i in 0..NX {
        if REFERENCE_ERROR_BOUND[i].is_finite() {
            let e = (reference[0][i] - guess[i]) / REFERENCE_ERROR_BOUND[i];
            excess += e * e;
        }
    }
    if excess > 1.0 && excess.is_finite() {
        // In units of the bound: the error at stage 0, and the bound along the horizon, growing by
        // REFERENCE_APPROACH_RATE per second (the point chased moves towards the reference).
        let error = sqrt(excess);
        for (k, row) in reference.iter_mut().enumerate() {
            let bound = 1.0 + REFERENCE_APPROACH_RATE * DT * k as Real;
            if bound >= error {
                break;
            }
            let cut = 1.0 - bound / error;
            for i in 0..NX {
                if REFERENCE_ERROR_BOUND[i].is_finite() {
                    row[i] -= (reference0[i] - guess[i]) * cut;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::continuous_jacobians;

    type M2 = [[Real; 2]; 2];

    fn mat_mul(a: &M2, b: &M2) -> M2 {
        let mut c = [[0.0; 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
            }
        }
        c
    }

    /// For linear ẋ = Ac x + Bc u one RK4 substep is x⁺ = P x + Q Bc u with
    /// P = I + hA + (hA)²/2 + (hA)³/6 + (hA)⁴/24 and
    /// Q = h (I + hA/2 + (hA)²/6 + (hA)³/24); hand-expanded here.
    fn rk4_matrices() -> (M2, [Real; 2]) {
        let (ac, bc) = continuous_jacobians(&[0.0; 2], &[0.0]);
        let ha = [[H * ac[0][0], H * ac[0][1]], [H * ac[1][0], H * ac[1][1]]];
        let ha2 = mat_mul(&ha, &ha);
        let ha3 = mat_mul(&ha2, &ha);
        let ha4 = mat_mul(&ha3, &ha);
        let mut p = [[0.0; 2]; 2];
        let mut q = [[0.0; 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                let id = if i == j { 1.0 } else { 0.0 };
                p[i][j] = id + ha[i][j] + ha2[i][j] / 2.0 + ha3[i][j] / 6.0 + ha4[i][j] / 24.0;
                q[i][j] = H * (id + ha[i][j] / 2.0 + ha2[i][j] / 6.0 + ha3[i][j] / 24.0);
            }
        }
        // Compose SUBSTEPS = 2 substeps: x⁺ = P(Px + QBu) + QBu.
        let qb = [
            q[0][0] * bc[0][0] + q[0][1] * bc[1][0],
            q[1][0] * bc[0][0] + q[1][1] * bc[1][0],
        ];
        let pp = mat_mul(&p, &p);
        let b_total = [
            p[0][0] * qb[0] + p[0][1] * qb[1] + qb[0],
            p[1][0] * qb[0] + p[1][1] * qb[1] + qb[1],
        ];
        (pp, b_total)
    }

    #[test]
    fn linear_model_matches_hand_expanded_rk4() {
        assert_eq!(SUBSTEPS, 2);
        let (ad, bd) = rk4_matrices();
        let x = [0.3, -1.2];
        let u = [0.7];
        let next = discrete_dynamics(&x, &u);
        for i in 0..2 {
            let expect = ad[i][0] * x[0] + ad[i][1] * x[1] + bd[i] * u[0];
            assert!((next[i] - expect).abs() < 1e-14, "state {i}: {} vs {expect}", next[i]);
        }
        let (a, b) = discrete_jacobians(&x, &u);
        for i in 0..2 {
            for j in 0..2 {
                assert!((a[i][j] - ad[i][j]).abs() < 1e-14);
            }
            assert!((b[i][0] - bd[i]).abs() < 1e-14);
        }
    }

    #[test]
    fn angles_wrap_onto_the_circle() {
        let pi = TAU / 2.0;
        assert_eq!(wrap_angle(0.25), 0.25);
        assert!((wrap_angle(TAU + 0.25) - 0.25).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * TAU - 0.25) + 0.25).abs() < 1e-12);
        assert!((wrap_angle(pi + 0.1) - (0.1 - pi)).abs() < 1e-12);
        assert!(wrap_angle(1e300).is_finite() && wrap_angle(Real::NAN).is_nan());
    }

    #[test]
    fn a_far_reference_is_translated_to_the_bound_and_approaches_at_the_rate() {
        // Bound 20 on state 0, growing at 1/s (2 per sample of 0.1 s): the window at 100 seen from
        // 0 starts at 20 and comes 2 closer to 100 per sample until it is the reference itself.
        assert_eq!(
            (REFERENCE_ERROR_BOUND[0], REFERENCE_APPROACH_RATE, DT),
            (20.0, 1.0, 0.1)
        );
        let mut r = [[100.0, 3.0]; N + 1];
        condition_reference(&mut r, &[0.0, -1.0]);
        for (k, row) in r.iter().enumerate() {
            let expect = (20.0 + 2.0 * k as Real).min(100.0);
            assert!((row[0] - expect).abs() < 1e-12, "stage {k}: {} vs {expect}", row[0]);
            assert_eq!(row[1], 3.0, "unbounded state untouched");
        }
        // Idempotent, and within the bound nothing changes.
        let once = r;
        condition_reference(&mut r, &[0.0, -1.0]);
        assert_eq!(r, once);
        let mut near = [[15.0, 3.0]; N + 1];
        condition_reference(&mut near, &[0.0, 0.0]);
        assert_eq!(near, [[15.0, 3.0]; N + 1]);
    }

    #[test]
    fn disturbances_are_bounded() {
        assert_eq!(bound_disturbance(&[0.0, 0.05]), [0.0, 0.05]);
        assert_eq!(bound_disturbance(&[1e300, -1e300]), [0.0, -0.1]);
        assert_eq!(bound_disturbance(&[0.01, -0.2]), [0.0, -0.1]);
    }

    #[test]
    fn linearization_state_equals_discrete_dynamics() {
        let x = [1.0, 2.0];
        let u = [-0.5];
        let (next, _, _) = discrete_linearization(&x, &u);
        assert_eq!(next, discrete_dynamics(&x, &u));
    }

    #[test]
    fn one_sample_decays_like_the_exact_solution() {
        // Free response of the stable oscillator: RK4 (h = 0.05) is close to exp(Ac DT).
        let x = [1.0, 0.0];
        let next = discrete_dynamics(&x, &[0.0]);
        // Exact: ωd = sqrt(K − C²/4), x(t) = e^{−Ct/2}(cos ωd t + C/(2ωd) sin ωd t).
        let wd = libm::sqrt(4.0 - 0.0625);
        let t = DT;
        let exact = libm::exp(-0.25 * t) * (libm::cos(wd * t) + 0.25 / wd * libm::sin(wd * t));
        assert!((next[0] - exact).abs() < 1e-6, "{} vs {exact}", next[0]);
    }
}
