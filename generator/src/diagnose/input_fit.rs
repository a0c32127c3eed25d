//! The input-response candidates one channel at a time: `latency` (a pure delay per input
//! channel) and `actuator_lag` (a first-order lag per input channel or dynamic row). Each channel
//! is scanned on its grid against the model so far ([`scan_channel`]); the significant channels
//! that do not make the held-out free runs worse are kept ([`keep_channels`]) and scored together.
//! (`channel_response`, the joint delay + lag + gain fit, is [`super::response_fit`].)

use super::catalogue::inputs::{delay_grid, InputTransform, LAG_CHANNELS};
use super::catalogue::EffectKind;
use super::design::{seen_f, SegBase, CHUNK};
use super::fit::profile_sigma;
use super::horizon_fit::Bracket;
use super::horizon_rule::horizon_errors;
use super::problem::{AfterSums, Current, HorizonErrors, Problem, State};
use super::score::{lr_z, Rules, Sums};
use super::scored::{finish, under, Candidate, InputParam, Install, Params, Scored};

/// A channel's scan: its parameter, the dynamic rows it acts on and, per fit, the value that
/// fit's training data chose.
struct ChannelScan {
    param: InputParam,
    aff: Vec<usize>,
    chosen: Vec<f64>,
}

/// Evaluate `latency` (a delay per input channel) or `actuator_lag` (a first-order lag per input
/// channel or dynamic row): scan every channel, keep the significant ones that do not make the
/// held-out free runs worse, and score them together.
pub(crate) fn evaluate(p: &Problem, state: &State, cur: &Current, kind: EffectKind, rules: &Rules) -> Candidate {
    let thrust_named = state.linear.iter().any(|k| {
        matches!(
            k,
            EffectKind::ThrustGain | EffectKind::ThrustDecay | EffectKind::GroundEffect
        )
    });
    let channels = match kind {
        EffectKind::Latency => 4,
        _ => LAG_CHANNELS,
    };
    let mut scans: Vec<ChannelScan> = (0..channels)
        .filter_map(|j| {
            let aff = affected_rows(p, j, thrust_named);
            (!aff.is_empty()).then(|| scan_channel(p, state, cur, kind, j, aff, rules))
        })
        .collect();
    if kind == EffectKind::Latency {
        refine_over_the_horizon(p, state, &mut scans);
    }
    let (used, after_horizon) = keep_channels(p, state, cur, kind, &mut scans);
    score(p, state, cur, kind, rules, scans, used, after_horizon)
}

/// The kept channels' delays refined on the training free runs, between the one-step optimum and
/// the residual cross-correlation's delay ([`super::horizon_fit`]); each fit's own scanned value
/// moves by the same amount (cross-validation folds).
fn refine_over_the_horizon(p: &Problem, state: &State, scans: &mut [ChannelScan]) {
    let mut kept: Vec<usize> = (0..scans.len()).filter(|&q| scans[q].param.kept).collect();
    kept.sort_by(|&a, &b| scans[b].param.z.total_cmp(&scans[a].param.z));
    let channels: Vec<Bracket> = kept
        .iter()
        .map(|&q| {
            let j = scans[q].param.input;
            Bracket::between(j, scans[q].param.value, p.seeds[j])
        })
        .collect();
    let refined = super::horizon_fit::refine_delays(p, state, &channels);
    let max = p.max_delay();
    for (&q, v) in kept.iter().zip(refined) {
        let scan = &mut scans[q];
        let shift = v - scan.param.value;
        if shift.abs() < 1e-12 {
            continue;
        }
        scan.param.one_step = Some(scan.param.value);
        scan.param.seed = p.seeds[scan.param.input];
        scan.param.value = v;
        for c in scan.chosen.iter_mut() {
            *c = (*c + shift).clamp(0.0, max);
        }
    }
}

/// The dynamic rows channel j acts on (input j's rows, or the lag channel's own row); with a
/// thrust effect named, an input acting on a translational row acts on all three.
fn affected_rows(p: &Problem, j: usize, thrust_named: bool) -> Vec<usize> {
    let aff: Vec<usize> = if j < 4 {
        (0..6).filter(|&c| p.input_rows[j][c]).collect()
    } else {
        vec![j - 4]
    };
    if j < 4 && thrust_named && aff.iter().any(|&c| c < 3) {
        [0, 1, 2]
            .into_iter()
            .chain(aff.into_iter().filter(|&c| c >= 3))
            .collect()
    } else {
        aff
    }
}

/// Scan channel j: delays on the grid (whole samples, then quarter samples around the best),
/// or no lag and the lag grid; the value of every fit, the likelihood-ratio z and the profile σ.
fn scan_channel(
    p: &Problem,
    state: &State,
    cur: &Current,
    kind: EffectKind,
    j: usize,
    aff: Vec<usize>,
    rules: &Rules,
) -> ChannelScan {
    let fin = p.final_fit();
    let dt = p.dt();
    let o = &p.options;
    let scope = p.scope(state, (j < 4).then_some(j), j >= 4);
    let mut points: Vec<Point> = Vec::new();
    let add = |points: &mut Vec<Point>, v: f64| {
        if points.iter().any(|q| (q.value - v).abs() < 1e-12) {
            return;
        }
        let tr = with_channel(&state.transform, kind, j, v);
        points.push(Point {
            value: v,
            sums: under(p, state, &tr, None),
        });
    };
    match kind {
        EffectKind::Latency => {
            // Whole samples (every `step` samples up to `max`, then every sample around the
            // best), then quarter samples around the best.
            let (max, step) = (p.max_delay(), p.delay_step_samples());
            let inside = |v: f64| v >= 0.0 && v <= max + 1e-12;
            for v in delay_grid(max / dt, step, dt).into_iter().filter(|v| inside(*v)) {
                add(&mut points, v);
            }
            let centre = points[argmin(&points, fin, &aff)].value;
            let reach = step as i64 - 1;
            for q in -reach..=reach {
                let v = centre + q as f64 * dt;
                if inside(v) {
                    add(&mut points, v);
                }
            }
            let centre = points[argmin(&points, fin, &aff)].value;
            for q in [-0.75, -0.5, -0.25, 0.25, 0.5, 0.75] {
                let v = centre + q * dt;
                if inside(v) {
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
    drop(scope);
    points.sort_by(|a, b| a.value.total_cmp(&b.value));
    let chosen: Vec<f64> = (0..p.fits.len())
        .map(|i| points[argmin(&points, i, &aff)].value)
        .collect();
    let best = argmin(&points, fin, &aff);
    let value = points[best].value;
    // τ of the residual before (training data of the final fit), as in `finish`.
    let tau = cur.before.train_tau;
    let before = cur.before.train();
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
    // A delay at the end of the scan is not an estimate: the optimum may lie beyond it.
    let at_edge = kind == EffectKind::Latency && value >= p.max_delay() - 0.5 * dt;
    let not_kept = if value > 0.0 && z <= rules.min_z {
        Some(format!("z = {z:.2} is not above {}", rules.min_z))
    } else if value > 0.0 && at_edge {
        Some(format!(
            "{value:.3} s is at the edge of the scan (0 … {:.3} s): no estimate",
            p.max_delay()
        ))
    } else {
        None
    };
    ChannelScan {
        param: InputParam {
            input: j,
            value,
            one_step: None,
            seed: None,
            sigma,
            z,
            kept: z > rules.min_z && value > 0.0 && !at_edge,
            not_kept,
        },
        aff,
        chosen,
    }
}

/// Kept channels, strongest first; a lag channel is left out where a stronger one already acts
/// on its rows (an input lag and the lag of a row it drives are alternatives, not a pair), and
/// any channel that makes the held-out free runs worse on top of the ones kept before it
/// ([`super::horizon_rule`]). Returns the channels used (the strongest one if none is kept) and
/// the held-out horizon errors with the kept ones, when computed.
fn keep_channels(
    p: &Problem,
    state: &State,
    cur: &Current,
    kind: EffectKind,
    scans: &mut [ChannelScan],
) -> (Vec<usize>, Option<HorizonErrors>) {
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
    (used, after_horizon)
}

/// The combined effect of the `used` channels, per fit with its own scanned values, scored.
#[allow(clippy::too_many_arguments)]
fn score(
    p: &Problem,
    state: &State,
    cur: &Current,
    kind: EffectKind,
    rules: &Rules,
    scans: Vec<ChannelScan>,
    used: Vec<usize>,
    after_horizon: Option<HorizonErrors>,
) -> Candidate {
    let segs = p.data.variant(state.destale);
    let mut after = AfterSums::new(p, segs.len());
    for (i, th) in state.theta.iter().enumerate() {
        let mut tr = state.transform;
        for &q in &used {
            tr = with_channel(&tr, kind, scans[q].param.input, scans[q].chosen[i]);
        }
        for (s, seg) in segs.iter().enumerate() {
            if !after.wants(i, s) {
                continue;
            }
            let b = SegBase::under(seg, &tr, || seen_f(seg, p.base, &tr));
            b.chunks(&p.ctx, &state.linear, CHUNK, |k0, d| {
                after.add(p, i, s, k0, &d.residual(&state.linear, th));
            });
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
