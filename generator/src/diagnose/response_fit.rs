//! `channel_response`: per input channel j, a pure delay d_j, a first-order lag τ_j and a gain k_j
//! fitted together — the model sees k_j · lag_τ(u_j(t − d_j)) — where `latency` and
//! `actuator_lag` fit one of them alone.
//!
//! The scan: (d, τ) on a grid (delays in whole samples from 0 to `max_delay_samples`, every
//! [`COARSE_STEP`] first, then every sample and quarter samples around the best; τ ∈ {0} ∪ [`LAGS`]), each
//! point scored by the training objective Σ_c ln SSE_c over the rows the input drives (as the
//! single-effect scans, [`super::candidate`]); the delay the residual cross-correlation finds
//! (`seed`, the "where" analysis) is always a grid point. At the chosen (d, τ) the gain is fitted
//! by least squares on the filtered regressor L[f(x, ū) − f(x, ū with ū_j = 0)] (exact for rows
//! linear in the input). σ of d and τ from the profile curvature along each axis, σ of k from the
//! least squares. A channel is part of the effect when its likelihood-ratio z is above the rule's
//! threshold, it moved (d > 0 or τ > 0), and the held-out free runs are not worse with it (on top of
//! the channels kept before it, strongest first).
//!
//! `channel_response` is named over `latency` or `actuator_lag` only when its score beats theirs by
//! [`super::select::RESPONSE_MARGIN`] (significant or not): a pure delay costs it two parameters
//! more per channel (ΔBIC), and its gain and lag absorb part of the base model's own errors.

use super::catalogue::inputs::InputTransform;
use super::catalogue::EffectKind;
use super::data::SegData;
use super::design::SegBase;
use super::fit::profile_sigma;
use super::horizon_rule::horizon_errors;
use super::problem::{AfterSums, Current, Problem, State};
use super::residuals::filter;
use super::score::{lr_z, Rules, Sums};
use super::scored::{finish, under, Candidate, ChannelFit, Install, Params, Scored};

/// The longest delay scanned is at least this, s.
pub const MIN_SCAN_DELAY: f64 = 0.4;

/// The step of the coarse delay scan, s, in the whole number of samples nearest to it (2 samples
/// at 30 Hz, 7 at 100 Hz); the fine scan then takes every sample within one step of the best.
pub const COARSE_STEP: f64 = 1.0 / 15.0;

/// The coarse scan's step in samples of `dt` (at least 1).
fn coarse_samples(dt: f64) -> usize {
    let n = (COARSE_STEP / dt).round();
    if n.is_finite() && n >= 1.0 {
        n as usize
    } else {
        1
    }
}

/// The time constants scanned besides 0 (no lag), s.
pub const LAGS: [f64; 8] = [0.02, 0.04, 0.07, 0.1, 0.15, 0.2, 0.3, 0.5];

fn with(tr: &InputTransform, j: usize, d: f64, tau: f64, gain: Option<f64>) -> InputTransform {
    let mut t = *tr;
    t.delay[j] = d;
    t.lag[j] = (tau > 0.0).then_some(tau);
    t.gain[j] = gain;
    t
}

/// The filtered gain regressor of input j under `tr` at a segment's interior samples.
fn gain_column(p: &Problem, seg: &SegData, tr: &InputTransform, j: usize) -> Vec<[f64; 6]> {
    let u = tr.apply(&seg.u, seg.dt);
    let g: Vec<[f64; 6]> = seg
        .x
        .iter()
        .zip(&u)
        .map(|(x, u)| {
            let f = tr.model_f(p.base, x, u);
            let mut u0 = *u;
            u0[j] = 0.0;
            let f0 = tr.model_f(p.base, x, &u0);
            std::array::from_fn(|c| f[6 + c] - f0[6 + c])
        })
        .collect();
    filter(&seg.kernel, &g, seg.len())
}

/// Least squares of the final fit's residual under `tr` on input j's gain column over the rows
/// `aff` of its training segments, one segment at a time: (a, σ²-free variance 1/ΦᵀΦ); the gain
/// is 1 + a.
fn gain_fit(p: &Problem, state: &State, tr: &InputTransform, j: usize, aff: &[usize]) -> (f64, f64) {
    let fin = p.final_fit();
    let segs = p.data.variant(state.destale);
    let (mut aa, mut ab) = (0.0, 0.0);
    for &s in &p.fits[fin].train {
        let seg = &segs[s];
        let res = SegBase::under(seg, tr, || p.seen_f(seg, tr)).residual(&p.ctx, &state.linear, &state.theta[fin]);
        let col = gain_column(p, seg, tr, j);
        for (k, (r, c)) in res.iter().zip(&col).enumerate() {
            if p.mask[s][k] {
                for &ch in aff {
                    aa += c[ch] * c[ch];
                    ab += c[ch] * r[ch];
                }
            }
        }
    }
    if aa > 0.0 {
        (ab / aa, 1.0 / aa)
    } else {
        (0.0, 0.0)
    }
}

fn objective(s: &Sums, aff: &[usize]) -> f64 {
    aff.iter().map(|&c| s.sse[c].max(1e-300).ln()).sum()
}

/// One channel's scan on the final fit's training data: the best (d, τ) and the profile σ.
struct Scan {
    delay: f64,
    lag: f64,
    delay_sigma: Option<f64>,
    lag_sigma: Option<f64>,
    train_after: Sums,
}

fn scan(p: &Problem, state: &State, j: usize, aff: &[usize], tau_c: &[f64; 6], seed: Option<f64>) -> Scan {
    let fin = p.final_fit();
    let dt = p.dt();
    // At least 0.4 s (a real autopilot's command delay reaches 0.2 s, plus its lag).
    let max_d = p.options.max_delay_samples.max((MIN_SCAN_DELAY / dt).ceil());
    let _scope = p.scope(state, Some(j), false);
    let mut points: Vec<(f64, f64, Sums)> = Vec::new();
    let add = |points: &mut Vec<(f64, f64, Sums)>, d: f64, tau: f64| {
        if d < -1e-12 || d > max_d * dt + 1e-9 {
            return;
        }
        let d = d.max(0.0);
        if points
            .iter()
            .any(|q| (q.0 - d).abs() < 1e-9 && (q.1 - tau).abs() < 1e-12)
        {
            return;
        }
        let sums = under(p, state, &with(&state.transform, j, d, tau, None), None);
        points.push((d, tau, sums[fin].0));
    };
    let best_of = |points: &[(f64, f64, Sums)]| -> usize {
        (0..points.len())
            .min_by(|&a, &b| objective(&points[a].2, aff).total_cmp(&objective(&points[b].2, aff)))
            .unwrap_or(0)
    };
    let taus_all: Vec<f64> = std::iter::once(0.0).chain(LAGS).collect();
    // Coarse: every COARSE_STEP (and the seed), every τ.
    let step = coarse_samples(dt);
    let coarse: Vec<f64> = (0..=max_d.floor() as usize)
        .step_by(step)
        .map(|n| n as f64 * dt)
        .chain(seed)
        .collect();
    for &d in &coarse {
        for &tau in &taus_all {
            add(&mut points, d, tau);
        }
    }
    // Fine: within a coarse step of the best, every sample, at its τ and the neighbouring ones;
    // then quarter samples at the best τ.
    let b = best_of(&points);
    let (d0, t0) = (points[b].0, points[b].1);
    let ti = taus_all.iter().position(|t| *t == t0).unwrap_or(0);
    let near_taus: Vec<f64> = taus_all[ti.saturating_sub(1)..(ti + 2).min(taus_all.len())].to_vec();
    let reach = step as i64 - 1;
    for &tau in &near_taus {
        for q in (-reach..=reach).filter(|&q| q != 0) {
            add(&mut points, d0 + q as f64 * dt, tau);
        }
    }
    let b = best_of(&points);
    let (d1, t1) = (points[b].0, points[b].1);
    for q in [-0.75, -0.5, -0.25, 0.25, 0.5, 0.75] {
        add(&mut points, d1 + q * dt, t1);
    }
    let b = best_of(&points);
    let (d, tau) = (points[b].0, points[b].1);
    // Profiles along each axis through the best point.
    let ell = |s: &Sums| -> f64 {
        -0.5 * aff
            .iter()
            .map(|&c| s.n as f64 / tau_c[c] * s.sse[c].max(1e-300).ln())
            .sum::<f64>()
    };
    let axis = |delay_axis: bool| -> Option<f64> {
        let mut line: Vec<(f64, f64)> = points
            .iter()
            .filter(|q| if delay_axis { q.1 == tau } else { (q.0 - d).abs() < 1e-9 })
            .map(|q| (if delay_axis { q.0 } else { q.1 }, ell(&q.2)))
            .collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
        let at = line.iter().position(|q| q.0 == if delay_axis { d } else { tau })?;
        (at > 0 && at + 1 < line.len()).then(|| {
            profile_sigma(
                [line[at - 1].0, line[at].0, line[at + 1].0],
                [line[at - 1].1, line[at].1, line[at + 1].1],
            )
        })?
    };
    Scan {
        delay: d,
        lag: tau,
        delay_sigma: axis(true),
        lag_sigma: axis(false),
        train_after: points[b].2,
    }
}

/// Evaluate `channel_response` against `state`; `seeds[j]`: the cross-correlation's delay of
/// input j, if the "where" analysis found one.
pub(crate) fn evaluate(p: &Problem, state: &State, cur: &Current, rules: &Rules) -> Candidate {
    let tau_c = cur.before.train_tau;
    let before = cur.before.train();
    let mut fits: Vec<ChannelFit> = Vec::new();
    let mut affs: Vec<Vec<usize>> = Vec::new();
    for j in 0..4 {
        let aff: Vec<usize> = (0..6).filter(|&c| p.input_rows[j][c]).collect();
        if aff.is_empty() {
            continue;
        }
        let seed = p.seeds[j];
        let sc = scan(p, state, j, &aff, &tau_c, seed);
        let tr = with(&state.transform, j, sc.delay, sc.lag, None);
        let (a, var) = gain_fit(p, state, &tr, j, &aff);
        let z = lr_z(&before, &sc.train_after, &tau_c, &aff);
        let moved = sc.delay > 0.0 || sc.lag > 0.0;
        let not_kept = if !moved {
            Some("neither a delay nor a lag helps".to_string())
        } else if z.is_nan() || z <= rules.min_z {
            Some(format!("z = {z:.2} is not above {}", rules.min_z))
        } else if 1.0 + a <= 0.0 {
            Some(format!("gain {:.3} is not positive", 1.0 + a))
        } else {
            None
        };
        // σ of the gain: the residual variance of the driven rows after, τ-inflated.
        let s2 = aff
            .iter()
            .map(|&c| sc.train_after.sse[c] / sc.train_after.n.max(1) as f64 * tau_c[c])
            .sum::<f64>()
            / aff.len() as f64;
        fits.push(ChannelFit {
            input: j,
            delay: sc.delay,
            delay_sigma: sc.delay_sigma,
            lag: sc.lag,
            lag_sigma: sc.lag_sigma,
            gain: 1.0 + a,
            gain_sigma: (var * s2).sqrt(),
            seed,
            z,
            kept: not_kept.is_none(),
            not_kept,
        });
        affs.push(aff);
    }
    // Kept channels, strongest first, each on top of the ones kept before it: the horizon rule.
    let mut order: Vec<usize> = (0..fits.len()).filter(|&q| fits[q].kept).collect();
    order.sort_by(|&a, &b| fits[b].z.total_cmp(&fits[a].z));
    let mut accepted = (state.transform, cur.horizon.clone());
    let mut used = Vec::new();
    for q in order {
        let f = &fits[q];
        let trial = with(&accepted.0, f.input, f.delay, f.lag, Some(f.gain));
        if cur.horizon.n == 0 {
            used.push(q);
            accepted.0 = trial;
            continue;
        }
        let errors = horizon_errors(
            p,
            &State {
                transform: trial,
                ..state.clone()
            },
        );
        match accepted.1.objection(&errors) {
            None => {
                used.push(q);
                accepted = (trial, errors);
            }
            Some(why) => {
                fits[q].kept = false;
                fits[q].not_kept = Some(why);
            }
        }
    }
    let after_horizon = (!used.is_empty() && cur.horizon.n > 0).then(|| accepted.1.clone());
    if used.is_empty() {
        if let Some(q) = (0..fits.len()).max_by(|&a, &b| fits[a].z.total_cmp(&fits[b].z)) {
            used.push(q);
            let f = &fits[q];
            accepted.0 = with(&state.transform, f.input, f.delay, f.lag, Some(f.gain));
        }
    }
    let transform = accepted.0;
    let mut after = AfterSums::new(p, p.data.variant(state.destale).len());
    under(p, state, &transform, Some(&mut after));
    let mut channels: Vec<usize> = used.iter().flat_map(|&q| affs[q].clone()).collect();
    channels.sort_unstable();
    channels.dedup();
    let z = used.iter().map(|&q| fits[q].z).fold(0.0, f64::max);
    let after_state = State {
        transform,
        ..state.clone()
    };
    let install = Install::Response(used.iter().map(|&q| fits[q].clone()).collect());
    let scored = Scored {
        kind: EffectKind::ChannelResponse,
        scored: channels.clone(),
        channels,
        params: Params::Response(fits),
        install,
        k: 3 * used.len(),
        z: Some(z),
        invalid: Vec::new(),
        after_state,
        after_horizon,
    };
    finish(p, cur, &after, scored, rules)
}
