//! Fitting and scoring one candidate against the current state ([`super::select`]).
//!
//! - **Linear effects**: weighted least squares of the vx vy vz residual on the filtered columns of
//!   the named linear effects and the candidate jointly ([`super::select::fit_linear`]). Standard
//!   errors σ_θ = √(diag((ΦᵀWΦ)⁻¹) s² τ̄), s² the weighted residual variance and τ̄ the mean
//!   integrated autocorrelation time of the vx vy vz residuals; z = max_i |θ_i|/σ_i.
//! - **Latency, actuator lag**: per input channel j, the delay (0 … max samples: whole samples,
//!   then quarter samples around the best) or the time constant (a logarithmic grid) is scanned;
//!   nothing else is refitted (0, no delay or lag, is a grid point). Each fit takes the value minimising Σ_c ln SSE_c over its training
//!   samples (c the channels that depend on u_j). σ from the curvature of the profile
//!   ℓ = −½ Σ_c (N/τ_c) ln SSE_c; z the likelihood-ratio z against the current model. Channels
//!   with z above the rule's threshold make up the effect (else the best channel alone, reported).
//! - **Stale samples**: the residual of the data with stale rows interpolated; z the
//!   likelihood-ratio z on the training data.

use super::catalogue::inputs::{delay_grid, InputTransform, LAG_CHANNELS};
use super::catalogue::linear::columns;
use super::catalogue::{EffectKind, Family};
use super::design::{design, design_from, seen_f};
use super::fit::{profile_sigma, MAX_LAG};
use super::horizon_rule::{horizon_errors, HorizonErrors};
use super::score::{delta_bic, lr_z, reduction, sums_masked, taus, Rules, Sums};
use super::select::{fit_linear, Current, Problem, State};

/// A scanned input parameter of one channel.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct InputParam {
    /// Input index (u_vz, u_roll, u_pitch, u_yaw_rate).
    pub input: usize,
    /// Delay or time constant, s (fit on all training data).
    pub value: f64,
    pub sigma: Option<f64>,
    /// Likelihood-ratio z of this channel alone.
    pub z: f64,
    /// Part of the effect: z above the threshold, no stronger kept channel on the same rows,
    /// and the held-out free runs not worse with it.
    pub kept: bool,
    /// Why a channel that moved is not part of the effect.
    pub not_kept: Option<String>,
}

/// The fitted parameters of a candidate (fit on all training data).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Params {
    /// In the order of [`columns`](super::catalogue::linear::parameter_names).
    Linear {
        values: Vec<f64>,
        sigma: Vec<f64>,
    },
    Input(Vec<InputParam>),
    /// Per input channel: delay, lag and gain fitted together.
    Response(Vec<super::response_fit::ChannelFit>),
    /// Per loop (roll, pitch, yaw).
    Loop(Vec<super::loop_fit::LoopFit>),
    Stale {
        train_rows: usize,
        train_total: usize,
        holdout_rows: usize,
        holdout_total: usize,
    },
    NotApplicable,
}

/// What naming the candidate changes in the state.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Install {
    /// θ of the named linear effects and this one, per fit.
    Linear(Vec<Vec<f64>>),
    /// (input, value) of the channels that make up the effect.
    Input(Vec<(usize, f64)>),
    /// The channels that make up a channel response.
    Response(Vec<super::response_fit::ChannelFit>),
    /// The loops' parameters (fit on all training data).
    Loop([Option<super::catalogue::loops::LoopParams>; super::catalogue::loops::NLOOPS]),
    Stale,
    Nothing,
}

/// A candidate's fit and score in one round.
#[derive(Clone, Debug)]
pub(crate) struct Candidate {
    pub kind: EffectKind,
    /// Dynamic channels (0 = vx … 5 = yaw_rate) the effect acts on; RMSEs and the reduction are
    /// reported over these.
    pub channels: Vec<usize>,
    pub params: Params,
    pub install: Install,
    pub train_before: Sums,
    pub train_after: Sums,
    pub test_before: Sums,
    pub test_after: Sums,
    /// Mean effective sample size N/τ over the scored channels (training, held out), τ of the
    /// residual before the candidate.
    pub train_n_eff: f64,
    pub test_n_eff: f64,
    /// Parameters added.
    pub k: usize,
    pub z: f64,
    pub delta_bic_train: f64,
    /// The score: held-out ΔBIC (lower is better).
    pub delta_bic_test: f64,
    pub reduction: f64,
    /// The reduction as a share of the base model's held-out RMSE (= `reduction` in round 1).
    pub reduction_of_base: f64,
    /// Held-out horizon rule ([`super::horizon_rule`]): mean over the 12 states of the MSE ratio
    /// after/before of free runs over the horizon (None when not evaluated: another rule failed).
    pub horizon_ratio: Option<f64>,
    pub significant: bool,
    /// Why it is not significant (empty when it is).
    pub reasons: Vec<String>,
}

/// Per-fit residuals after the candidate, per segment (empty where not needed).
pub(crate) type After = Vec<Vec<Vec<[f64; 6]>>>;

/// Evaluate `kind` against `state`.
pub(crate) fn evaluate(p: &Problem, state: &State, cur: &Current, kind: EffectKind, rules: &Rules) -> Candidate {
    match kind.family() {
        Family::Linear => linear(p, state, cur, kind, rules),
        Family::Input => input(p, state, cur, kind, rules),
        Family::Loop => super::loop_fit::evaluate(p, state, cur, rules),
        Family::Response => super::response_fit::evaluate(p, state, cur, rules),
        Family::Data => stale(p, state, cur, rules),
    }
}

pub(crate) struct Scored {
    pub kind: EffectKind,
    pub channels: Vec<usize>,
    pub scored: Vec<usize>,
    pub params: Params,
    pub install: Install,
    pub k: usize,
    /// z from standard errors (linear effects); the likelihood-ratio z otherwise.
    pub z: Option<f64>,
    /// Why the fitted parameters are not acceptable (outside the model format's range).
    pub invalid: Vec<String>,
    /// The model with the candidate added, for the horizon rule, and its horizon errors if
    /// already known.
    pub after_state: State,
    pub after_horizon: Option<HorizonErrors>,
}

/// Sums with every channel's SSE at least N × floor.
fn floored(mut s: Sums, floor: &[f64; 6]) -> Sums {
    for c in 0..6 {
        s.sse[c] = s.sse[c].max(s.n as f64 * floor[c]);
    }
    s
}

pub(crate) fn finish(p: &Problem, cur: &Current, after: &After, s: Scored, rules: &Rules) -> Candidate {
    let fin = p.final_fit();
    let train = &p.fits[fin].train;
    let train_before = sums_masked(&cur.residual[fin], train, &p.mask);
    let train_after = sums_masked(&after[fin], train, &p.mask);
    // τ of the residual before the candidate: one sample size for every candidate of a round
    // (the residual after would reward a candidate for leaving a rougher residual).
    let parts: Vec<&[[f64; 6]]> = train.iter().map(|&t| cur.residual[fin][t].as_slice()).collect();
    let train_tau = taus(&parts, &s.scored, MAX_LAG);
    let (mut test_before, mut test_after) = (Sums::default(), Sums::default());
    let mut test_parts: Vec<&[[f64; 6]]> = Vec::new();
    for i in p.test_fits() {
        test_before.add(&sums_masked(&cur.residual[i], &p.fits[i].test, &p.mask));
        test_after.add(&sums_masked(&after[i], &p.fits[i].test, &p.mask));
        test_parts.extend(p.fits[i].test.iter().map(|&t| cur.residual[i][t].as_slice()));
    }
    let test_tau = taus(&test_parts, &s.scored, p.options.savgol.window);
    let (train_before, train_after) = (floored(train_before, &p.floor), floored(train_after, &p.floor));
    let (test_before, test_after) = (floored(test_before, &p.floor), floored(test_after, &p.floor));
    let mean_n_eff = |n: usize, tau: &[f64; 6]| {
        s.scored.iter().map(|&c| n as f64 / tau[c]).sum::<f64>() / s.scored.len().max(1) as f64
    };
    let (train_n_eff, test_n_eff) = (
        mean_n_eff(train_after.n, &train_tau),
        mean_n_eff(test_after.n, &test_tau),
    );
    let delta_bic_train = delta_bic(&train_before, &train_after, &train_tau, &s.scored, s.k);
    let delta_bic_test = delta_bic(&test_before, &test_after, &test_tau, &s.scored, s.k);
    let red = reduction(&test_before, &test_after, &s.channels);
    // The same as a share of the base model's gap: what this candidate adds to the reduction.
    let base = floored(cur.base_test, &p.floor);
    let gained = reduction(&base, &test_after, &s.channels) - reduction(&base, &test_before, &s.channels);
    let z =
        s.z.unwrap_or_else(|| lr_z(&train_before, &train_after, &train_tau, &s.scored));
    let mut reasons = Vec::new();
    if s.params == Params::NotApplicable {
        reasons.push("not applicable: the data have no stale rows".to_string());
    } else {
        if delta_bic_test >= rules.max_delta_bic {
            reasons.push(format!(
                "held-out ΔBIC {delta_bic_test:.1} is not below {}",
                rules.max_delta_bic
            ));
        }
        if red < rules.min_reduction {
            reasons.push(format!(
                "held-out RMSE reduction {:.1} % is below {:.1} %",
                100.0 * red,
                100.0 * rules.min_reduction
            ));
        } else if gained < rules.min_reduction {
            reasons.push(format!(
                "held-out RMSE reduction {:.1} % of the base model's RMSE is below {:.1} %",
                100.0 * gained,
                100.0 * rules.min_reduction
            ));
        }
        reasons.extend(s.invalid.iter().cloned());
        if z.is_nan() || z <= rules.min_z {
            reasons.push(format!("z = {z:.2} is not above {}", rules.min_z));
        }
    }
    // The horizon rule, only for a candidate that passes the others (free runs cost time).
    let mut horizon_ratio = None;
    if reasons.is_empty() {
        let after = s.after_horizon.unwrap_or_else(|| horizon_errors(p, &s.after_state));
        horizon_ratio = cur.horizon.ratio(&after);
        reasons.extend(cur.horizon.objection(&after));
    }
    Candidate {
        kind: s.kind,
        channels: s.channels,
        params: s.params,
        install: s.install,
        train_before,
        train_after,
        test_before,
        test_after,
        train_n_eff,
        test_n_eff,
        k: s.k,
        z,
        delta_bic_train,
        delta_bic_test,
        reduction: red,
        reduction_of_base: gained,
        horizon_ratio,
        significant: reasons.is_empty(),
        reasons,
    }
}

fn linear(p: &Problem, state: &State, cur: &Current, kind: EffectKind, rules: &Rules) -> Candidate {
    let mut kinds = state.linear.clone();
    kinds.push(kind);
    let own = columns(kind);
    let mut after: After = Vec::new();
    let mut per_fit = Vec::new();
    let fin = p.final_fit();
    let (mut values, mut sigma) = (Vec::new(), Vec::new());
    for (i, fold) in p.fits.iter().enumerate() {
        let (theta, cov, w) = fit_linear(&cur.designs, &fold.train, &kinds, &cur.residual[i], &p.mask);
        let res: Vec<Vec<[f64; 6]>> = cur.designs.iter().map(|d| d.residual(&kinds, &theta)).collect();
        if i == fin {
            let s = sums_masked(&res, &fold.train, &p.mask);
            let ptot = theta.len();
            let dof = (3 * s.n).saturating_sub(ptot).max(1) as f64;
            let s2 = (0..3).map(|c| w[c] * s.sse[c]).sum::<f64>() / dof;
            let parts: Vec<&[[f64; 6]]> = fold.train.iter().map(|&t| res[t].as_slice()).collect();
            let tau = taus(&parts, &[0, 1, 2], MAX_LAG);
            let tau_mean = (tau[0] + tau[1] + tau[2]) / 3.0;
            let first = ptot - own;
            values = theta[first..].to_vec();
            sigma = (first..ptot).map(|q| (cov[(q, q)] * s2 * tau_mean).sqrt()).collect();
        }
        per_fit.push(theta);
        after.push(res);
    }
    let z = values
        .iter()
        .zip(&sigma)
        .map(|(v, s)| if *s > 0.0 { v.abs() / s } else { 0.0 })
        .filter(|z| z.is_finite())
        .fold(0.0, f64::max);
    // A parameter significantly outside the model format's range is not a physical effect (a
    // negative drag); one that is not significant is written clamped.
    let (clamped, _) = super::corrected::clamp(kind, &values);
    let names = super::catalogue::linear::parameter_names(kind);
    let invalid = (0..values.len())
        .filter(|&q| clamped[q] != values[q] && (values[q] - clamped[q]).abs() > rules.min_z * sigma[q])
        .map(|q| {
            format!(
                "{}.{} = {:.4} ± {:.4} is outside the model format's range (written as {})",
                kind, names[q], values[q], sigma[q], clamped[q]
            )
        })
        .collect();
    let channels = if kind == EffectKind::GroundEffect || super::design::vertical_only(kind) {
        vec![2]
    } else {
        vec![0, 1, 2]
    };
    let after_state = State {
        linear: kinds,
        theta: per_fit.clone(),
        ..state.clone()
    };
    let scored = Scored {
        kind,
        channels,
        scored: vec![0, 1, 2],
        params: Params::Linear { values, sigma },
        install: Install::Linear(per_fit),
        k: own,
        z: Some(z),
        invalid,
        after_state,
        after_horizon: None,
    };
    finish(p, cur, &after, scored, rules)
}

/// The role of each segment in each fit.
#[derive(Clone, Copy, PartialEq)]
enum Role {
    None,
    Train,
    Test,
}

fn roles(p: &Problem, n: usize) -> Vec<Vec<Role>> {
    p.fits
        .iter()
        .map(|f| {
            let mut r = vec![Role::None; n];
            for &s in &f.train {
                r[s] = Role::Train;
            }
            for &s in &f.test {
                r[s] = Role::Test;
            }
            r
        })
        .collect()
}

/// The model `state` describes with the input transform `tr`: per fit, the (training, held-out)
/// sums of its residuals and, with `keep`, the residuals themselves (per fit, per segment; empty
/// for segments the fit does not use).
pub(crate) fn under(p: &Problem, state: &State, tr: &InputTransform, keep: bool) -> (Vec<(Sums, Sums)>, After) {
    let segs = p.data.variant(state.destale);
    let role = roles(p, segs.len());
    let mut sums = vec![(Sums::default(), Sums::default()); p.fits.len()];
    let mut after: After = vec![vec![Vec::new(); segs.len()]; p.fits.len()];
    for (s, seg) in segs.iter().enumerate() {
        if role.iter().all(|r| r[s] == Role::None) {
            continue;
        }
        let fs = seen_f(seg, p.base, tr);
        let d = design_from(seg, &fs, &p.ctx, &state.linear);
        for (i, th) in state.theta.iter().enumerate() {
            if role[i][s] == Role::None {
                continue;
            }
            let res = d.residual(&state.linear, th);
            let one = sums_masked(std::slice::from_ref(&res), &[0], std::slice::from_ref(&p.mask[s]));
            match role[i][s] {
                Role::Train => sums[i].0.add(&one),
                _ => sums[i].1.add(&one),
            }
            if keep {
                after[i][s] = res;
            }
        }
    }
    (sums, after)
}

/// `tr` with channel j's delay or lag set to v (v = 0: none).
fn with_channel(tr: &InputTransform, kind: EffectKind, j: usize, v: f64) -> InputTransform {
    let mut t = *tr;
    match kind {
        EffectKind::Latency => t.delay[j] = v,
        _ => t.set_lag(j, (v > 0.0).then_some(v)),
    }
    t
}

/// One scanned grid point: per fit, training and test sums.
struct Point {
    value: f64,
    sums: Vec<(Sums, Sums)>,
}

/// Σ_c ln SSE_c over `aff` (the objective of the scan; N is common to all channels).
fn objective(s: &Sums, aff: &[usize]) -> f64 {
    aff.iter().map(|&c| s.sse[c].max(1e-300).ln()).sum()
}

fn input(p: &Problem, state: &State, cur: &Current, kind: EffectKind, rules: &Rules) -> Candidate {
    let segs = p.data.variant(state.destale);
    let role = roles(p, segs.len());
    let fin = p.final_fit();
    let thrust_named = state.linear.iter().any(|k| {
        matches!(
            k,
            EffectKind::ThrustGain | EffectKind::ThrustDecay | EffectKind::GroundEffect
        )
    });
    let dt = p.dt();
    let o = &p.options;
    // Evaluate one transform: per fit, training and test sums.
    let eval = |tr: &InputTransform| -> Vec<(Sums, Sums)> { under(p, state, tr, false).0 };
    // Per channel: the scan.
    struct ChannelScan {
        param: InputParam,
        aff: Vec<usize>,
        chosen: Vec<f64>,
    }
    let mut scans: Vec<ChannelScan> = Vec::new();
    let channels = match kind {
        EffectKind::Latency => 4,
        _ => LAG_CHANNELS,
    };
    for j in 0..channels {
        let mut aff: Vec<usize> = if j < 4 {
            (0..6).filter(|&c| p.input_rows[j][c]).collect()
        } else {
            vec![j - 4]
        };
        if j < 4 && thrust_named && aff.iter().any(|&c| c < 3) {
            aff = [0, 1, 2]
                .into_iter()
                .chain(aff.into_iter().filter(|&c| c >= 3))
                .collect();
        }
        if aff.is_empty() {
            continue;
        }
        let mut points: Vec<Point> = Vec::new();
        let add = |points: &mut Vec<Point>, v: f64| {
            if points.iter().any(|q| (q.value - v).abs() < 1e-12) {
                return;
            }
            let tr = with_channel(&state.transform, kind, j, v);
            points.push(Point {
                value: v,
                sums: eval(&tr),
            });
        };
        match kind {
            EffectKind::Latency => {
                for v in delay_grid(o.max_delay_samples, 1.0, dt) {
                    add(&mut points, v);
                }
                let best = argmin(&points, fin, &aff);
                let centre = points[best].value;
                for q in [-0.75, -0.5, -0.25, 0.25, 0.5, 0.75] {
                    let v = centre + q * dt;
                    if v >= 0.0 && v <= o.max_delay_samples * dt + 1e-12 {
                        add(&mut points, v);
                    }
                }
            }
            _ => {
                // 0: no lag (the current model), so "no lag helps" is a possible answer.
                for v in std::iter::once(0.0).chain(o.lag_grid.iter().copied()) {
                    add(&mut points, v);
                }
            }
        }
        points.sort_by(|a, b| a.value.total_cmp(&b.value));
        let chosen: Vec<f64> = (0..p.fits.len())
            .map(|i| points[argmin(&points, i, &aff)].value)
            .collect();
        let best = argmin(&points, fin, &aff);
        let value = points[best].value;
        // τ of the residual before (training data of the final fit), as in `finish`.
        let slices: Vec<&[[f64; 6]]> = p.fits[fin]
            .train
            .iter()
            .map(|&s| cur.residual[fin][s].as_slice())
            .collect();
        let tau = taus(&slices, &aff, MAX_LAG);
        let before = sums_masked(&cur.residual[fin], &p.fits[fin].train, &p.mask);
        let z = lr_z(&before, &points[best].sums[fin].0, &tau, &aff);
        let ell = |q: &Point| -> f64 {
            let s = &q.sums[fin].0;
            -0.5 * aff
                .iter()
                .map(|&c| s.n as f64 / tau[c] * s.sse[c].max(1e-300).ln())
                .sum::<f64>()
        };
        let sigma = (best > 0 && best + 1 < points.len())
            .then(|| {
                let (a, b, c) = (&points[best - 1], &points[best], &points[best + 1]);
                profile_sigma([a.value, b.value, c.value], [ell(a), ell(b), ell(c)])
            })
            .flatten();
        scans.push(ChannelScan {
            param: InputParam {
                input: j,
                value,
                sigma,
                z,
                kept: z > rules.min_z && value > 0.0,
                not_kept: (value > 0.0 && z <= rules.min_z).then(|| format!("z = {z:.2} is not above {}", rules.min_z)),
            },
            aff,
            chosen,
        });
    }
    // Kept channels, strongest first; a lag channel is left out where a stronger one already acts
    // on its rows (an input lag and the lag of a row it drives are alternatives, not a pair), and
    // any channel that makes the held-out free runs worse on top of the ones kept before it
    // ([`super::horizon_rule`]).
    let mut kept: Vec<usize> = (0..scans.len()).filter(|&q| scans[q].param.kept).collect();
    kept.sort_by(|&a, &b| scans[b].param.z.total_cmp(&scans[a].param.z));
    let mut used: Vec<usize> = Vec::new();
    let mut accepted = (state.transform, cur.horizon.clone());
    for q in kept {
        let overlaps = used
            .iter()
            .any(|&u| scans[u].aff.iter().any(|c| scans[q].aff.contains(c)));
        if kind != EffectKind::Latency && overlaps {
            scans[q].param.kept = false;
            scans[q].param.not_kept = Some("a stronger kept channel acts on the same rows".to_string());
            continue;
        }
        let trial = with_channel(&accepted.0, kind, scans[q].param.input, scans[q].param.value);
        let errors = if cur.horizon.n > 0 {
            horizon_errors(
                p,
                &State {
                    transform: trial,
                    ..state.clone()
                },
            )
        } else {
            accepted.1.clone()
        };
        match (cur.horizon.n > 0).then(|| accepted.1.objection(&errors)).flatten() {
            None => {
                used.push(q);
                accepted = (trial, errors);
            }
            Some(why) => {
                scans[q].param.kept = false;
                scans[q].param.not_kept = Some(why);
            }
        }
    }
    used.sort_unstable();
    // The kept channels' free runs were just computed.
    let after_horizon = (!used.is_empty() && cur.horizon.n > 0).then_some(accepted.1);
    if used.is_empty() {
        if let Some(q) = (0..scans.len()).max_by(|&a, &b| scans[a].param.z.total_cmp(&scans[b].param.z)) {
            used.push(q);
        }
    }
    // The combined effect, per fit with its own scanned values.
    let mut after: After = vec![vec![Vec::new(); segs.len()]; p.fits.len()];
    for (i, th) in state.theta.iter().enumerate() {
        let mut tr = state.transform;
        for &q in &used {
            tr = with_channel(&tr, kind, scans[q].param.input, scans[q].chosen[i]);
        }
        for (s, seg) in segs.iter().enumerate() {
            if role[i][s] == Role::None {
                continue;
            }
            let d = design(seg, p.base, &tr, &p.ctx, &state.linear);
            after[i][s] = d.residual(&state.linear, th);
        }
    }
    let mut channels: Vec<usize> = used.iter().flat_map(|&q| scans[q].aff.clone()).collect();
    channels.sort_unstable();
    channels.dedup();
    let z = used.iter().map(|&q| scans[q].param.z).fold(0.0, f64::max);
    let mut transform = state.transform;
    for &q in &used {
        transform = with_channel(&transform, kind, scans[q].param.input, scans[q].param.value);
    }
    let after_state = State {
        transform,
        ..state.clone()
    };
    let install = Install::Input(
        used.iter()
            .map(|&q| (scans[q].param.input, scans[q].param.value))
            .collect(),
    );
    let scored = Scored {
        kind,
        scored: channels.clone(),
        channels,
        params: Params::Input(scans.into_iter().map(|s| s.param).collect()),
        install,
        k: used.len(),
        z: Some(z),
        invalid: Vec::new(),
        after_state,
        after_horizon,
    };
    finish(p, cur, &after, scored, rules)
}

/// The grid point minimising the training objective of fit `i` (the first on ties).
fn argmin(points: &[Point], i: usize, aff: &[usize]) -> usize {
    let mut best = 0;
    for q in 1..points.len() {
        if objective(&points[q].sums[i].0, aff) < objective(&points[best].sums[i].0, aff) {
            best = q;
        }
    }
    best
}

fn stale(p: &Problem, state: &State, cur: &Current, rules: &Rules) -> Candidate {
    let all: Vec<usize> = (0..6).collect();
    let applicable = p.data.destaled.is_some() && !state.destale;
    let (after, params, install) = if applicable {
        let segs = p.data.variant(true);
        let designs: Vec<_> = segs
            .iter()
            .map(|s| design(s, p.base, &state.transform, &p.ctx, &state.linear))
            .collect();
        let after: After = state
            .theta
            .iter()
            .map(|th| designs.iter().map(|d| d.residual(&state.linear, th)).collect())
            .collect();
        let (train_rows, train_total) = p.data.stale_rows(false);
        let (holdout_rows, holdout_total) = p.data.stale_rows(true);
        (
            after,
            Params::Stale {
                train_rows,
                train_total,
                holdout_rows,
                holdout_total,
            },
            Install::Stale,
        )
    } else {
        (cur.residual.clone(), Params::NotApplicable, Install::Nothing)
    };
    let after_state = State {
        destale: applicable,
        ..state.clone()
    };
    let scored = Scored {
        kind: EffectKind::StaleSamples,
        channels: all.clone(),
        scored: all,
        params,
        install,
        k: 0,
        z: None,
        invalid: Vec::new(),
        after_state,
        after_horizon: None,
    };
    finish(p, cur, &after, scored, rules)
}
