//! The input delays (and, [`refine_loop_gains`], the named loops' gains) refined over the MPC
//! horizon; the delays between the two estimates `diagnose` has.
//!
//! The delay scan of `latency` ([`super::input_fit`]) minimises the one-step residual: it finds the
//! delay at which the model's next-sample predictions fit best. The residual analysis (the "where"
//! report's prewhitened cross-correlation of each command with its driven rate, `response_lags`)
//! finds another: the lag at which the command and the model's error are most alike. When the base
//! model's loops are not the aircraft's — a simulator's model on another aircraft, the case
//! `diagnose` exists for — the two disagree: the one-step optimum absorbs part of the loops'
//! mismatch (on `plants/m100_like.json` with a nominal-plant base, 0.058 s on roll and pitch
//! against the plant's 0.076 / 0.090 s), the cross-correlation peaks where the loop's own response
//! lag adds to the delay (0.133 s). The corrected model exists for the MPC, which predicts over N
//! samples; so each kept channel's delay is chosen *between* the two estimates by the training free
//! runs over the horizon:
//!
//! ```text
//! R(d) = mean_q MSE_q(d) / MSE_q(d₀)      12 states, free runs of N samples from every
//!                                         STRIDE s of training data (runs that diverge: R = ∞)
//! d_j  ← argmin R over [min(d₀,j, s_j), max(d₀,j, s_j)]: steps of h from d₀,j and the bracket's
//!        ends, then ± h/2 around the best; h the whole number of half samples nearest to
//!        GRID_STEP = 1/60 s, at least one (half a sample at 30 Hz and below, 1.5 samples at
//!        100 Hz)
//! ```
//!
//! d₀ the one-step delays of all kept channels, s_j channel j's cross-correlation delay (no seed:
//! no refinement), refined one channel at a time in the order of their strength (z), the others at
//! their current values. The held-out data are not used: they score the result as for every
//! candidate. On m100_like: roll 0.058 → 0.075 s, pitch 0.058 → 0.083 s, vertical and yaw
//! unchanged (their free runs want no longer delay); the held-out horizon RMSE improves
//! (docs/diagnosis.md).

use super::catalogue::loops::LoopParams;
use super::horizon_rule::add_errors;
use super::problem::{HorizonErrors, Problem, State};

/// Training free runs start every STRIDE seconds (a search: sparser than the horizon rule's; every
/// 6th sample at 30 Hz, every 20th at 100 Hz).
const STRIDE: f64 = 0.2;

/// The step of the delay grid, s, rounded to whole half samples (half a sample at 30 Hz; module
/// docs).
const GRID_STEP: f64 = 1.0 / 60.0;

/// The step of the delay grid for samples of `dt`: the whole number of half samples nearest to
/// [`GRID_STEP`], at least one.
fn grid_step(dt: f64) -> f64 {
    let half = 0.5 * dt;
    let k = (GRID_STEP / half).round();
    if k.is_finite() && k > 1.0 {
        k * half
    } else {
        half
    }
}

/// R of `e` against `reference` (module docs); ∞ when `e` diverges more often or has no samples.
fn objective(reference: &HorizonErrors, e: &HorizonErrors) -> f64 {
    if e.diverged > reference.diverged {
        return f64::INFINITY;
    }
    reference.ratio(e).unwrap_or(f64::INFINITY)
}

/// A channel to refine: its input, its one-step delay and the bracket it may move in (s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Bracket {
    pub input: usize,
    pub start: f64,
    pub lo: f64,
    pub hi: f64,
}

impl Bracket {
    /// Between the one-step delay `start` and the cross-correlation's `seed` (none: `start` alone).
    pub fn between(input: usize, start: f64, seed: Option<f64>) -> Self {
        let s = seed.unwrap_or(start);
        Self {
            input,
            start,
            lo: start.min(s),
            hi: start.max(s),
        }
    }

    /// The grid of the first pass: steps of `step` from `start` both ways, and the ends.
    fn grid(&self, step: f64) -> Vec<f64> {
        let mut g = vec![self.start, self.lo, self.hi];
        for dir in [-1.0, 1.0] {
            let mut v = self.start + dir * step;
            while v > self.lo + 1e-9 && v < self.hi - 1e-9 {
                g.push(v);
                v += dir * step;
            }
        }
        g
    }
}

/// The refined delays (s) of `channels` (strongest first) on the model `state` describes (its
/// other channels as they are). Without training runs: the one-step delays.
pub(crate) fn refine_delays(p: &Problem, state: &State, channels: &[Bracket]) -> Vec<f64> {
    let fin = p.final_fit();
    let train = &p.fits[fin].train;
    let dt = p.dt();
    let errors = |delays: &[f64]| {
        let mut s = state.clone();
        for (c, &d) in channels.iter().zip(delays) {
            s.transform.delay[c.input] = d;
        }
        let mut e = HorizonErrors::default();
        add_errors(p, &s, fin, train, STRIDE, &mut e);
        e
    };
    let mut values: Vec<f64> = channels.iter().map(|c| c.start).collect();
    if channels.iter().all(|c| c.hi - c.lo < 1e-9) {
        return values;
    }
    let reference = errors(&values);
    if reference.n == 0 {
        return values;
    }
    let mut current = 1.0;
    for (idx, c) in channels.iter().enumerate() {
        if c.hi - c.lo < 1e-9 {
            continue;
        }
        let mut tried: Vec<(f64, f64)> = vec![(c.start, current)];
        let try_value = |v: f64, tried: &mut Vec<(f64, f64)>, values: &[f64]| {
            let v = v.clamp(c.lo, c.hi);
            if tried.iter().any(|t| (t.0 - v).abs() < 1e-9) {
                return;
            }
            let mut trial = values.to_vec();
            trial[idx] = v;
            tried.push((v, objective(&reference, &errors(&trial))));
        };
        let step = grid_step(dt);
        for v in c.grid(step) {
            try_value(v, &mut tried, &values);
        }
        let coarse = best(&tried);
        for o in [-0.5, 0.5] {
            try_value(coarse.0 + o * step, &mut tried, &values);
        }
        let (v, r) = best(&tried);
        values[idx] = v;
        current = r;
    }
    values
}

/// The named loops' gains and couplings refined over the horizon, as the delays are: the one-step
/// least squares of [`super::loop_fit`] fits the loop's row to noisy rate differences, which
/// attenuates it and reads a delayed loop as a slower one, while the MPC predicts with the loop
/// over N samples. Each named loop moves by coordinate search on R (module docs): its gain over
/// g · 2^(±i/4), i = 1 … 4; then its coupling over c ± i/8, i = 1 … 4; then its gain over
/// g · 2^(±1/16), g · 2^(±1/8) — a step is taken only when R falls; one loop at a time (roll,
/// pitch, yaw), the others at their current values. Training free runs only; the held-out data
/// score the result.
pub(crate) fn refine_loop_gains(p: &Problem, state: &mut State) {
    let fin = p.final_fit();
    let train = p.fits[fin].train.clone();
    let errors = |s: &State| {
        let mut e = HorizonErrors::default();
        add_errors(p, s, fin, &train, STRIDE, &mut e);
        e
    };
    if state.transform.loops.iter().all(Option::is_none) {
        return;
    }
    let reference = errors(state);
    if reference.n == 0 {
        return;
    }
    for l in 0..state.transform.loops.len() {
        let Some(start) = state.transform.loops[l] else {
            continue;
        };
        // R with loop l at p, the other loops at their current values.
        let score = |p: LoopParams, state: &State| {
            let mut s = state.clone();
            s.transform.loops[l] = Some(p);
            objective(&reference, &errors(&s))
        };
        let mut current = (start, score(start, state));
        // The gain (multiplicative steps), the coupling (additive), then the gain once more, finer.
        let passes: [(bool, &[f64]); 3] = [
            (true, &[-1.0, -0.75, -0.5, -0.25, 0.25, 0.5, 0.75, 1.0]),
            (false, &[-0.5, -0.375, -0.25, -0.125, 0.125, 0.25, 0.375, 0.5]),
            (true, &[-0.125, -0.0625, 0.0625, 0.125]),
        ];
        for (gain, steps) in passes {
            let from = current.0;
            for &d in steps {
                let p = if gain {
                    LoopParams {
                        gain: from.gain * 2f64.powf(d),
                        ..from
                    }
                } else {
                    LoopParams {
                        coupling: from.coupling + d,
                        ..from
                    }
                };
                if !(p.gain.is_finite() && p.gain > 0.0 && p.coupling.is_finite()) {
                    continue;
                }
                let r = score(p, state);
                if r < current.1 {
                    current = (p, r);
                }
            }
        }
        if current.1.is_finite() {
            state.transform.loops[l] = Some(current.0);
        }
    }
}

/// The (value, objective) with the smallest objective; the first on ties.
fn best(tried: &[(f64, f64)]) -> (f64, f64) {
    tried
        .iter()
        .copied()
        .fold((f64::NAN, f64::INFINITY), |b, t| if t.1 < b.1 { t } else { b })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn best_takes_the_smallest_objective_and_the_first_on_ties() {
        let tried = [(0.1, 1.0), (0.2, 0.9), (0.3, 0.9), (0.4, f64::INFINITY)];
        assert_eq!(best(&tried), (0.2, 0.9));
    }

    /// The grid step is half a sample at 30 Hz (bit for bit) and below, the whole number of half
    /// samples nearest to 1/60 s on faster logs.
    #[test]
    fn the_grid_step_is_in_seconds() {
        assert_eq!(grid_step(1.0 / 30.0), 0.5 / 30.0);
        assert_eq!(grid_step(0.0334), 0.0167);
        assert_eq!(grid_step(0.1), 0.05);
        assert!((grid_step(0.01) - 0.015).abs() < 1e-15);
        assert!((grid_step(0.02) - 0.02).abs() < 1e-15);
    }

    /// The bracket spans the two estimates in either order; its grid stays inside it.
    #[test]
    fn the_bracket_lies_between_the_estimates() {
        let dt = 0.1;
        let b = Bracket::between(1, 0.05, Some(0.2));
        assert_eq!((b.lo, b.hi), (0.05, 0.2));
        let g = b.grid(grid_step(dt));
        assert!(g.iter().all(|v| (0.05 - 1e-12..=0.2 + 1e-12).contains(v)), "{g:?}");
        assert!(g.iter().any(|v| (v - 0.1).abs() < 1e-12) && g.contains(&0.2) && g.contains(&0.05));
        let b = Bracket::between(0, 0.3, Some(0.1));
        assert_eq!((b.lo, b.hi), (0.1, 0.3));
        assert_eq!(
            Bracket::between(0, 0.3, None),
            Bracket {
                input: 0,
                start: 0.3,
                lo: 0.3,
                hi: 0.3
            }
        );
    }

    #[test]
    fn diverging_runs_are_never_better() {
        let reference = HorizonErrors {
            sse: [1.0; 12],
            n: 10,
            runs: 2,
            diverged: 0,
        };
        let mut e = reference.clone();
        e.sse = [0.1; 12];
        assert!((objective(&reference, &e) - 0.1).abs() < 1e-12);
        e.diverged = 1;
        assert_eq!(objective(&reference, &e), f64::INFINITY);
    }
}
