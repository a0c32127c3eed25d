//! The horizon rule: an effect is named only if it does not make the held-out free runs over the
//! MPC horizon worse. The one-step score can reward a correction that fits the next sample while
//! the model drifts further over N samples (a lag added to a base row that is itself too slow
//! makes the loop more oscillatory); the corrected model exists for the MPC, which predicts over
//! the horizon.
//!
//! ```text
//! R = mean_i  MSE_i,after / MSE_i,before      over the 12 states (yaw wrapped), free runs of N
//!                                             samples from a held-out sample every STRIDE s
//! ```
//!
//! R > 1 (or more diverged runs after than before) fails the rule. For `latency` and
//! `actuator_lag` every kept channel must pass it on top of the stronger ones
//! ([`super::candidate`]). Runs use the parameters of each test fit (cross-validation: each fold's
//! named linear parameters; the scanned delays and lags of the fit on all training data).

use super::problem::{HorizonErrors, Problem, State};
use super::shrink::{run, wrapped};
use crate::logs::{on_ground, run_touches_ground};

/// A run starts every STRIDE seconds of held-out data (every 3rd sample at 30 Hz, every 10th at
/// 100 Hz: the runs overlap by most of the horizon either way).
pub(crate) const STRIDE: f64 = 0.1;

/// Every how many samples of period `dt` a run starts, for a stride of `seconds`: the whole
/// samples within it, ⌊seconds/dt⌋, allowing 1 % of a sample of timestamp jitter (at least 1; at
/// 30 and 33.3 Hz every 3rd sample for 0.1 s, every 6th for 0.2 s).
pub(crate) fn stride_samples(seconds: f64, dt: f64) -> usize {
    if dt > 0.0 && (seconds / dt).is_finite() {
        ((seconds / dt + 0.01).floor() as usize).max(1)
    } else {
        1
    }
}

/// The horizon errors of the model `state` describes, on the held-out data of every test fit.
pub(crate) fn horizon_errors(p: &Problem, state: &State) -> HorizonErrors {
    let mut out = HorizonErrors::default();
    for i in p.test_fits() {
        add_errors(p, state, i, &p.fits[i].test, STRIDE, &mut out);
    }
    out
}

/// Add to `out` the free runs of N samples of fit `i`'s model (`state` with that fit's parameters)
/// from a sample every `stride` seconds ([`stride_samples`]) of the segments `segs` (runs that
/// touch the ground left out).
pub(crate) fn add_errors(p: &Problem, state: &State, i: usize, segs: &[usize], stride: f64, out: &mut HorizonErrors) {
    let horizon = p.options.horizon;
    let data = p.data.variant(state.destale);
    let aug = p.augmented(state, i);
    for &s in segs {
        let seg = &data[s];
        let seen = aug.seen_inputs(seg);
        let ground = on_ground(&seg.x);
        for k in (0..seg.len().saturating_sub(horizon)).step_by(stride_samples(stride, seg.dt)) {
            if run_touches_ground(&ground, k, horizon) {
                continue;
            }
            out.runs += 1;
            let pred = run(&aug, seg, &seen, k, horizon);
            if pred.len() < horizon {
                out.diverged += 1;
            }
            for (j, pr) in pred.iter().enumerate() {
                let o = &seg.x[k + j + 1];
                let pr = wrapped(pr, o);
                for q in 0..12 {
                    out.sse[q] += (pr[q] - o[q]).powi(2);
                }
                out.n += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strides_are_in_seconds() {
        assert_eq!(stride_samples(STRIDE, 1.0 / 30.0), 3);
        assert_eq!(stride_samples(STRIDE, 0.0334), 3);
        assert_eq!(stride_samples(STRIDE, 0.01), 10);
        assert_eq!(stride_samples(STRIDE, 0.02), 5);
        assert_eq!(stride_samples(0.2, 1.0 / 30.0), 6);
        assert_eq!(stride_samples(0.2, 0.0333334), 6);
        assert_eq!(stride_samples(0.2, 0.03), 6);
        assert_eq!(stride_samples(STRIDE, 0.03), 3);
        assert_eq!(stride_samples(0.2, 0.01), 20);
        assert_eq!(stride_samples(STRIDE, 1.0), 1);
        assert_eq!(stride_samples(STRIDE, 0.0), 1);
    }

    #[test]
    fn the_ratio_is_the_mean_per_state_mse_ratio() {
        let before = HorizonErrors {
            sse: [2.0; 12],
            n: 10,
            runs: 4,
            diverged: 0,
        };
        let mut after = before.clone();
        after.sse[0] = 4.0; // twice the error in x
        after.sse[1] = 0.0; // none in y
                            // (2 + 0 + 10 · 1)/12 = 1.
        assert_eq!(before.ratio(&after), Some(1.0));
        assert!(before.objection(&after).is_none());
        after.sse[2] = 2.2;
        assert!(before.ratio(&after).unwrap() > 1.0 && before.objection(&after).is_some());
        // Fewer samples after (a diverged run) are compared per sample, and fail the rule.
        let mut shorter = before.clone();
        shorter.n = 5;
        shorter.sse = [1.0; 12];
        shorter.diverged = 1;
        assert_eq!(before.ratio(&shorter), Some(1.0));
        assert!(before.objection(&shorter).is_some());
        // Without data the rule does not apply.
        assert!(HorizonErrors::default().objection(&after).is_none());
    }
}
