//! Offset-free tracking: a disturbance observer for the model's one-sample prediction.
//!
//! A model identified on one aircraft and flown on another (or on the same one with drag, a
//! heavier battery, other gains) leaves a slowly varying error in every prediction: the MPC then
//! tracks with a bias it does not see (on plants/m100_like.json the shipped models lag or cut the
//! spiral by 0.1–0.2 m at its 6 m/s, docs/validation.md). The observer estimates that error as a
//! disturbance e of the discrete dynamics,
//!
//! ```text
//! x⁺ = F(x, u) + e,
//! ```
//!
//! from the measurements themselves, and the solver predicts with it
//! (`Mpc::set_disturbance` of a generated crate; docs/mpc.md, "Offset-free tracking"):
//!
//! ```text
//! x̂ₖ = F(x̂ₖ₋₁, uₖ₋₁) + e              (the prediction from the last fresh measurement)
//! eᵢ ← clamp(eᵢ + L (xₖ,ᵢ − x̂ₖ,ᵢ) / m, ±bᵢ)   at a fresh measurement xₖ, m samples after the last
//! ```
//!
//! with the gain L (`DISTURBANCE_GAIN`) and the per-sample bound bᵢ (`DISTURBANCE_BOUND`: the
//! maximum acceleration times DT on vx, vy, vz, 0 on the states not estimated). The bound keeps a
//! model's transient errors (a 3.6 m approach at the tilt bound: 1.7 m/s²) out of the estimate;
//! the gain sets its time constant (about 1/L samples).
//!
//! **Stale measurements.** A measurement equal to the last fresh one in every state is a repeated
//! row of the estimator (21–40 % of the M100's and of m100_like's; docs/logs.md, "Stale rows"): it
//! changes nothing, and the prediction runs on to the next fresh one, whose error is then spread
//! over the m samples in between. After more than [`MAX_GAP`] samples without a fresh measurement
//! the next one restarts the prediction without updating e.
//!
//! The [`DelayCompensator`](crate::DelayCompensator) runs one when built
//! [`with_disturbance_observer`](crate::DelayCompensator::with_disturbance_observer): it knows the
//! inputs that acted on the aircraft over each sample (the delayed ones) and the dynamics F.

use crate::Real;

/// The longest run of samples without a fresh measurement over which an error is still spread.
pub const MAX_GAP: u32 = 4;

/// The update of the module docs at a fresh measurement `x`, `gap` samples after the last, whose
/// prediction is `predicted`: eᵢ ← clamp(eᵢ + L (xᵢ − x̂ᵢ)/m, ±bᵢ) on the rows with bᵢ > 0 (a
/// non-finite step leaves its row alone); nothing for a gap of 0 or above [`MAX_GAP`]. The one
/// definition [`DisturbanceObserver`] and uavgen's generic reference backend (states of run-time
/// number) both use; the slices are zipped, so the shortest sets the rows updated.
pub fn correct<R: Real>(gain: R, bound: &[R], estimate: &mut [R], x: &[R], predicted: &[R], gap: u32) {
    if gap == 0 || gap > MAX_GAP {
        return;
    }
    let m = R::from_u32(gap);
    let rows = estimate.iter_mut().zip(bound);
    for ((e, &b), (xi, pi)) in rows.zip(x.iter().zip(predicted)) {
        let step = gain * (*xi - *pi) / m;
        if b > R::ZERO && step.is_finite() {
            *e = (*e + step).clamp_to(-b, b);
        }
    }
}

/// The observer of the module docs for `NX` states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DisturbanceObserver<R, const NX: usize> {
    gain: R,
    bound: [R; NX],
    estimate: [R; NX],
    /// The prediction of the current sample's state from the last fresh measurement.
    predicted: [R; NX],
    /// The last fresh measurement (valid when `measured`).
    last: [R; NX],
    measured: bool,
    /// Samples since the last fresh measurement.
    gap: u32,
}

impl<R: Real, const NX: usize> DisturbanceObserver<R, NX> {
    /// An observer with gain L = `gain` (clamped into [0, 1]; NaN: 0, off) and the per-sample
    /// bounds `bound` (a generated crate's `DISTURBANCE_GAIN`, `DISTURBANCE_BOUND`). A state whose
    /// bound is 0, negative or NaN is not estimated. The estimate starts at 0.
    pub fn new(gain: R, bound: [R; NX]) -> Self {
        let gain = if gain.is_finite() {
            gain.clamp_to(R::ZERO, R::ONE)
        } else {
            R::ZERO
        };
        let mut b = bound;
        for v in b.iter_mut() {
            if v.is_nan() || *v <= R::ZERO {
                *v = R::ZERO;
            }
        }
        Self {
            gain,
            bound: b,
            estimate: [R::ZERO; NX],
            predicted: [R::ZERO; NX],
            last: [R::ZERO; NX],
            measured: false,
            gap: 0,
        }
    }

    /// The current estimate e (finite, |eᵢ| ≤ bᵢ).
    pub fn estimate(&self) -> &[R; NX] {
        &self.estimate
    }

    /// Whether it estimates anything (a positive gain and some positive bound).
    pub fn is_active(&self) -> bool {
        self.gain > R::ZERO && self.bound.iter().any(|b| *b > R::ZERO)
    }

    /// Forget the estimate and the last measurement.
    pub fn reset(&mut self) {
        self.estimate = [R::ZERO; NX];
        self.measured = false;
        self.gap = 0;
    }

    /// The measurement of the current sample. A non-finite one, or a repeat of the last fresh one
    /// (module docs), changes nothing.
    pub fn measure(&mut self, x: &[R; NX]) {
        if !x.iter().all(|v| v.is_finite()) || (self.measured && *x == self.last) {
            return;
        }
        if self.measured {
            correct(self.gain, &self.bound, &mut self.estimate, x, &self.predicted, self.gap);
        }
        self.last = *x;
        self.predicted = *x;
        self.measured = true;
        self.gap = 0;
    }

    /// Time advances by one sample over which `u` acted on the aircraft (each channel's delayed
    /// input): x̂ ← F(x̂, u) + e.
    pub fn advance<F: Fn(&[R; NX], &[R; NU]) -> [R; NX], const NU: usize>(&mut self, dynamics: &F, u: &[R; NU]) {
        if !self.measured || self.gap > MAX_GAP {
            return;
        }
        let mut next = dynamics(&self.predicted, u);
        for (n, e) in next.iter_mut().zip(&self.estimate) {
            *n += *e;
        }
        self.predicted = next;
        self.gap += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x = (position, velocity), u = acceleration; DT = 0.1.
    fn model(x: &[f64; 2], u: &[f64; 1]) -> [f64; 2] {
        [x[0] + 0.1 * x[1] + 0.005 * u[0], x[1] + 0.1 * u[0]]
    }

    #[test]
    fn a_constant_disturbance_is_found_within_its_bound() {
        // The plant has 0.5 m/s² more than the model: 0.05 m/s per sample on the velocity row.
        let mut obs = DisturbanceObserver::new(0.3, [0.0, 0.1]);
        assert!(obs.is_active());
        let mut x = [0.0, 0.0];
        for _ in 0..60 {
            obs.measure(&x);
            let u = [-0.2];
            let next = model(&x, &u);
            x = [next[0] + 0.0025, next[1] + 0.05];
            obs.advance(&model, &u);
        }
        let e = obs.estimate();
        assert_eq!(e[0], 0.0, "the position row is not estimated");
        assert!((e[1] - 0.05).abs() < 1e-6, "e = {e:?}");
    }

    #[test]
    fn the_bound_holds_and_nan_changes_nothing() {
        let mut obs = DisturbanceObserver::new(1.0, [0.0, 0.02]);
        obs.measure(&[0.0, 0.0]);
        obs.advance(&model, &[0.0]);
        obs.measure(&[0.0, 5.0]); // 5 m/s off in one sample
        assert_eq!(obs.estimate()[1], 0.02);
        let before = *obs.estimate();
        obs.advance(&model, &[0.0]);
        obs.measure(&[f64::NAN, 0.0]);
        assert_eq!(obs.estimate(), &before);
        // A NaN gain or bound switches the observer off.
        let off = DisturbanceObserver::new(f64::NAN, [f64::NAN, -1.0]);
        assert!(!off.is_active());
    }

    #[test]
    fn a_repeated_measurement_is_skipped_and_its_error_spread() {
        // The plant drifts 0.04 m/s per sample; every other measurement repeats the previous one.
        let mut obs = DisturbanceObserver::new(0.5, [0.0, 1.0]);
        let mut x = [0.0, 0.0];
        let mut shown = x;
        for k in 0..80 {
            if k % 2 == 0 {
                shown = x;
            }
            obs.measure(&shown);
            let next = model(&x, &[0.0]);
            x = [next[0] + 0.002, next[1] + 0.04];
            obs.advance(&model, &[0.0]);
        }
        assert!((obs.estimate()[1] - 0.04).abs() < 1e-6, "e = {:?}", obs.estimate());
    }

    #[test]
    fn a_long_gap_restarts_without_an_update() {
        let mut obs = DisturbanceObserver::new(1.0, [0.0, 1.0]);
        obs.measure(&[0.0, 0.0]);
        for _ in 0..=MAX_GAP {
            obs.advance(&model, &[0.0]);
        }
        obs.measure(&[0.0, 0.5]);
        assert_eq!(obs.estimate()[1], 0.0);
        obs.reset();
        assert_eq!(obs.estimate(), &[0.0, 0.0]);
    }
}
