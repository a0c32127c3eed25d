//! Greedy selection: every round evaluates each remaining candidate against the model augmented
//! with the effects named so far ([`super::candidate`]), names the best significant one (lowest
//! held-out ΔBIC among those that pass [`Rules`](super::score::Rules); between latency and
//! actuator lag see [`DELAY_MARGIN`]), refits the linear
//! parameters of all named effects jointly, and stops when no candidate is significant or
//! `max_effects` are named.
//!
//! Held-out data: the `--holdout` logs (one fit on the training logs, scored on them), or, without
//! them, cross-validation: leave one training log out (≥ 2 logs), else one segment (≥ 2 segments),
//! else one of `folds` consecutive parts of the lone segment. Linear parameters and the scanned
//! delay or lag of a candidate are fitted per fold on the other folds; the input transforms of
//! effects already named, and all reported parameters, come from the fit on all training data.

use super::augmented::Augmented;
use super::candidate::{evaluate, Candidate, Install};
use super::catalogue::inputs::{InputTransform, LAG_CHANNELS};
use super::catalogue::linear::{linear_kinds, Context};
use super::catalogue::EffectKind;
use super::data::Prepared;
use super::design::{design, Design};
use super::fit::Normal;
use super::horizon_rule::{horizon_errors, HorizonErrors};
use super::residuals::Base;
use super::score::{sums_masked, Rules, Sums};
use super::DiagnoseOptions;
use crate::logs::StalePolicy;
use std::ops::Range;

/// Training and test segments of one fit.
#[derive(Clone, Debug)]
pub(crate) struct Fold {
    pub train: Vec<usize>,
    pub test: Vec<usize>,
}

/// Everything fixed during the selection.
pub(crate) struct Problem<'a> {
    pub base: &'a Base,
    pub data: &'a Prepared,
    /// The fits: with held-out logs one (train → holdout); with cross-validation one per fold and
    /// a last one on all training data (no test).
    pub fits: Vec<Fold>,
    pub cv: bool,
    pub ctx: Context,
    pub options: &'a DiagnoseOptions,
    /// `input_rows[j][c]`: dynamic row c of the base model depends on input j (structurally).
    pub input_rows: [[bool; 6]; 4],
    /// Per channel, the smallest mean squared residual taken as real: (1e-8 × the RMS of the
    /// channel's derivative target)². Below it residuals are rounding, and an exact model would
    /// otherwise "improve" by fitting rounding noise.
    pub floor: [f64; 6],
    /// Per segment, per interior sample: counted in fits and scores — clear of the ground, and
    /// for held-out samples inside the training envelope ([`super::envelope`]).
    pub mask: Vec<Vec<bool>>,
    /// Per input, the delay the residual analysis's cross-correlation found (s), if any: a grid
    /// point of `channel_response`'s scan.
    pub seeds: [Option<f64>; 4],
}

impl Problem<'_> {
    /// The median sample period of the segments, s.
    pub fn dt(&self) -> f64 {
        let mut dts: Vec<f64> = self.data.raw.iter().map(|s| s.dt).collect();
        dts.sort_by(f64::total_cmp);
        dts.get(dts.len() / 2).copied().unwrap_or(0.0)
    }

    /// The fits whose test segments are scored.
    pub fn test_fits(&self) -> Range<usize> {
        if self.cv {
            0..self.fits.len() - 1
        } else {
            0..1
        }
    }

    /// The fit on all training data, whose parameters are reported and written.
    pub fn final_fit(&self) -> usize {
        self.fits.len() - 1
    }

    /// The model `state` describes with the parameters of fit `i`, to step exactly.
    pub fn augmented(&self, state: &State, i: usize) -> Augmented<'_> {
        let (linear, _) = super::corrected::linear_parameters(state, &state.theta[i]);
        Augmented {
            base: self.base,
            ctx: self.ctx,
            linear,
            transform: state.transform,
        }
    }
}

/// The cross-validation groups and folds over the prepared segments, or the single fit with
/// held-out logs. Returns (fits, cv).
pub(crate) fn folds(data: &Prepared) -> (Vec<Fold>, bool) {
    let train: Vec<usize> = (0..data.raw.len()).filter(|&s| !data.raw[s].holdout).collect();
    let test: Vec<usize> = (0..data.raw.len()).filter(|&s| data.raw[s].holdout).collect();
    if !test.is_empty() {
        return (vec![Fold { train, test }], false);
    }
    let logs: std::collections::BTreeSet<usize> = train.iter().map(|&s| data.raw[s].log).collect();
    let group = |s: usize| -> (usize, usize, usize) {
        let d = &data.raw[s];
        if logs.len() >= 2 {
            (d.log, 0, 0)
        } else {
            (d.log, d.segment, d.part)
        }
    };
    let groups: std::collections::BTreeSet<(usize, usize, usize)> = train.iter().map(|&s| group(s)).collect();
    let mut fits: Vec<Fold> = groups
        .iter()
        .map(|g| Fold {
            train: train.iter().copied().filter(|&s| group(s) != *g).collect(),
            test: train.iter().copied().filter(|&s| group(s) == *g).collect(),
        })
        .collect();
    fits.push(Fold { train, test: vec![] });
    (fits, true)
}

/// The effects named so far.
#[derive(Clone, Debug)]
pub(crate) struct State {
    pub destale: bool,
    pub transform: InputTransform,
    /// Named linear effects, in the order of their parameters in `theta`.
    pub linear: Vec<EffectKind>,
    /// Per fit: the concatenated parameters of `linear`.
    pub theta: Vec<Vec<f64>>,
    /// Named effects in order.
    pub named: Vec<EffectKind>,
}

impl State {
    /// Whether the transform's delays are named effects (`latency` or `channel_response`), to be
    /// written and backfitted.
    pub fn delays_named(&self) -> bool {
        self.named.contains(&EffectKind::Latency) || self.named.contains(&EffectKind::ChannelResponse)
    }

    /// No effect named yet; the base model's own input response in place.
    pub fn empty(fits: usize, base: &Base) -> Self {
        Self {
            destale: false,
            transform: InputTransform::of_base(base),
            linear: Vec::new(),
            theta: vec![Vec::new(); fits],
            named: Vec::new(),
        }
    }
}

/// The current designs and residuals (per fit, per segment).
pub(crate) struct Current {
    pub designs: Vec<Design>,
    pub residual: Vec<Vec<Vec<[f64; 6]>>>,
    /// The base model's held-out sums (of the first round), the reference of the reduction rule.
    pub base_test: Sums,
    /// The held-out horizon errors of the model so far ([`super::horizon_rule`]; empty outside
    /// the selection rounds).
    pub horizon: HorizonErrors,
}

pub(crate) fn current(p: &Problem, state: &State) -> Current {
    let segs = p.data.variant(state.destale);
    let kinds: Vec<EffectKind> = linear_kinds().collect();
    let designs: Vec<Design> = segs
        .iter()
        .map(|s| design(s, p.base, &state.transform, &p.ctx, &kinds))
        .collect();
    let residual = state
        .theta
        .iter()
        .map(|th| designs.iter().map(|d| d.residual(&state.linear, th)).collect())
        .collect();
    Current {
        designs,
        residual,
        base_test: Sums::default(),
        horizon: HorizonErrors::default(),
    }
}

/// Held-out sums of the current residuals over the test fits (scored samples).
pub(crate) fn test_sums(p: &Problem, residual: &[Vec<Vec<[f64; 6]>>]) -> Sums {
    let mut out = Sums::default();
    for i in p.test_fits() {
        out.add(&sums_masked(&residual[i], &p.fits[i].test, &p.mask));
    }
    out
}

/// Weighted least squares of the linear `kinds` on the vx vy vz residuals r⁰ of the `train`
/// segments. Weights 1/MSE_c per channel, from `start` (the residual before), then once more from
/// the fit's own residual. Returns θ, the unscaled covariance and the weights of the last pass.
pub(crate) fn fit_linear(
    designs: &[Design],
    train: &[usize],
    kinds: &[EffectKind],
    start: &[Vec<[f64; 6]>],
    mask: &[Vec<bool>],
) -> (Vec<f64>, nalgebra::DMatrix<f64>, [f64; 3]) {
    let p: usize = kinds.iter().map(|k| super::catalogue::linear::columns(*k)).sum();
    let weights_of = |res: &[Vec<[f64; 6]>]| -> [f64; 3] {
        let s = sums_masked(res, train, mask);
        let mse = s.mse();
        std::array::from_fn(|c| if mse[c] > 0.0 { 1.0 / mse[c] } else { 1.0 })
    };
    let mut w = weights_of(start);
    let mut out = (vec![0.0; p], nalgebra::DMatrix::zeros(p, p));
    for pass in 0..2 {
        let mut ne = Normal::new(p);
        let mut row = vec![0.0; p];
        for &s in train {
            let d = &designs[s];
            let cols: Vec<&Vec<[f64; 3]>> = kinds.iter().flat_map(|k| d.columns_of(*k)).collect();
            for (k, r) in d.r0.iter().enumerate() {
                if !mask[s][k] {
                    continue;
                }
                for c in 0..3 {
                    for (i, col) in cols.iter().enumerate() {
                        row[i] = col[k][c];
                    }
                    ne.add(&row, r[c], w[c]);
                }
            }
        }
        out = ne.solve();
        if pass == 0 {
            let res: Vec<Vec<[f64; 6]>> = designs.iter().map(|d| d.residual(kinds, &out.0)).collect();
            w = weights_of(&res);
        }
    }
    (out.0, out.1, w)
}

/// Refit the named linear effects jointly, per fit, on the current data variant and transform.
fn refit(p: &Problem, state: &mut State) {
    if state.linear.is_empty() {
        return;
    }
    let cur = current(p, state);
    for (i, fold) in p.fits.iter().enumerate() {
        let (theta, _, _) = fit_linear(&cur.designs, &fold.train, &state.linear, &cur.residual[i], &p.mask);
        state.theta[i] = theta;
    }
}

/// The named input channels: (effect, input index).
fn named_inputs(state: &State) -> Vec<(EffectKind, usize)> {
    let mut out = Vec::new();
    for j in 0..4 {
        if state.delays_named() && state.transform.delay[j] > 0.0 {
            out.push((EffectKind::Latency, j));
        }
    }
    for j in 0..LAG_CHANNELS {
        if state.transform.lag_of(j).is_some() {
            out.push((EffectKind::ActuatorLag, j));
        }
    }
    out
}

/// Backfitting after a new effect is named: each named delay or lag is scanned again with the
/// named linear effects refitted at every grid value (their profile), on all training data, then
/// the linear parameters are refitted per fit; twice. Without it an effect named first absorbs
/// part of one named later (a drag fitted before a delay of u_vz was known keeps a biased z
/// coefficient, and the remainder looks like a third effect).
fn backfit(p: &Problem, state: &mut State) {
    let inputs = named_inputs(state);
    if state.named.len() < 2 {
        return;
    }
    if inputs.is_empty() {
        super::loop_fit::refit(p, state);
        refit(p, state);
        return;
    }
    let fin = p.final_fit();
    let train = p.fits[fin].train.clone();
    let segs = p.data.variant(state.destale);
    let dt = p.dt();
    for _ in 0..2 {
        for &(kind, j) in &inputs {
            let current = match kind {
                EffectKind::Latency => state.transform.delay[j],
                _ => state.transform.lag_of(j).unwrap_or(0.0),
            };
            let grid: Vec<f64> = match kind {
                EffectKind::Latency => (-8..=8)
                    .map(|q| current + q as f64 * 0.25 * dt)
                    .filter(|v| *v > 0.0 && *v <= p.options.max_delay_samples * dt + 1e-12)
                    .collect(),
                _ => p.options.lag_grid.iter().copied().chain([current]).collect(),
            };
            let mut best = (f64::INFINITY, current);
            for g in grid {
                let mut tr = state.transform;
                match kind {
                    EffectKind::Latency => tr.delay[j] = g,
                    _ => tr.set_lag(j, Some(g)),
                }
                let designs: Vec<Design> = segs
                    .iter()
                    .enumerate()
                    .map(|(s, seg)| {
                        if train.contains(&s) {
                            design(seg, p.base, &tr, &p.ctx, &state.linear)
                        } else {
                            Design {
                                r0: Vec::new(),
                                cols: state.linear.iter().map(|k| (*k, Vec::new())).collect(),
                            }
                        }
                    })
                    .collect();
                let res: Vec<Vec<[f64; 6]>> = if state.linear.is_empty() {
                    designs.iter().map(|d| d.r0.clone()).collect()
                } else {
                    let start: Vec<Vec<[f64; 6]>> = designs.iter().map(|d| d.r0.clone()).collect();
                    let (theta, _, _) = fit_linear(&designs, &train, &state.linear, &start, &p.mask);
                    designs.iter().map(|d| d.residual(&state.linear, &theta)).collect()
                };
                let s = sums_masked(&res, &train, &p.mask);
                let objective: f64 = s.sse.iter().map(|v| v.max(1e-300).ln()).sum();
                if objective < best.0 {
                    best = (objective, g);
                }
            }
            match kind {
                EffectKind::Latency => state.transform.delay[j] = best.1,
                _ => state.transform.set_lag(j, Some(best.1)),
            }
        }
        super::loop_fit::refit(p, state);
        refit(p, state);
    }
}

/// Name `c` in `state`.
fn install(p: &Problem, state: &mut State, c: &Candidate) {
    match &c.install {
        Install::Linear(per_fit) => {
            state.linear.push(c.kind);
            state.theta = per_fit.clone();
        }
        Install::Input(values) => {
            for &(j, v) in values {
                match c.kind {
                    EffectKind::Latency => state.transform.delay[j] = v,
                    _ => state.transform.set_lag(j, Some(v)),
                }
            }
            refit(p, state);
        }
        Install::Response(fits) => {
            for f in fits {
                state.transform.delay[f.input] = f.delay;
                state.transform.lag[f.input] = (f.lag > 0.0).then_some(f.lag);
                state.transform.gain[f.input] = Some(f.gain);
            }
            refit(p, state);
        }
        Install::Loop(loops) => {
            state.transform.loops = *loops;
            refit(p, state);
        }
        Install::Stale => {
            state.destale = true;
            refit(p, state);
        }
        Install::Nothing => {}
    }
    state.named.push(c.kind);
    backfit(p, state);
}

/// `latency` is named over a significant `actuator_lag` only if its held-out ΔBIC is lower by more
/// than this factor. Both shift the response by about the same phase at low frequency; they part at
/// higher frequencies, where the base model's own errors are largest. On the plant simulator a
/// pure 0.1 s delay scores 1.5–1.9 × the lag, a 0.04 s motor lag (inside the autopilot's loops,
/// neither form exactly) 1.07–1.11 × in favour of the delay (docs/diagnose.md).
pub(crate) const DELAY_MARGIN: f64 = 1.25;

/// One round: every candidate evaluated against the state at its start.
#[derive(Clone, Debug)]
pub(crate) struct Round {
    pub candidates: Vec<Candidate>,
    pub named: Option<EffectKind>,
}

/// Apply the `interpolate` stale policy when the data have stale rows: `stale_samples` is
/// evaluated against the base model (for the report) and installed whatever its score.
fn stale_first(p: &Problem, state: &mut State, rounds: &mut Vec<Round>, rules: &Rules) -> bool {
    if p.options.stale != StalePolicy::Interpolate || p.data.destaled.is_none() {
        return false;
    }
    let mut cur = current(p, state);
    cur.base_test = test_sums(p, &cur.residual);
    cur.horizon = horizon_errors(p, state);
    let c = evaluate(p, state, &cur, EffectKind::StaleSamples, rules);
    rounds.push(Round {
        candidates: vec![c.clone()],
        named: Some(EffectKind::StaleSamples),
    });
    install(p, state, &c);
    true
}

/// The greedy selection; `progress(done, total, name)` after each candidate.
pub(crate) fn select(
    p: &Problem,
    kinds: &[EffectKind],
    rules: &Rules,
    progress: &mut dyn FnMut(usize, usize, &str),
) -> (State, Vec<Round>) {
    let mut state = State::empty(p.fits.len(), p.base);
    let mut rounds = Vec::new();
    let mut done = 0;
    let mut base_test: Option<Sums> = None;
    // The stale-row policy acts before any effect: with `interpolate` the stale rows are missing
    // samples from the start (scored as a data finding in a round of its own, always applied and
    // not counted against `max_effects`); with `keep` the logs are used as recorded.
    let data_effects = usize::from(stale_first(p, &mut state, &mut rounds, rules));
    let kinds: Vec<EffectKind> = kinds
        .iter()
        .copied()
        .filter(|k| *k != EffectKind::StaleSamples || p.options.stale == StalePolicy::Interpolate)
        .collect();
    let kinds = kinds.as_slice();
    loop {
        let remaining: Vec<EffectKind> = kinds.iter().copied().filter(|k| !state.named.contains(k)).collect();
        if remaining.is_empty() {
            break;
        }
        let mut cur = current(p, &state);
        let base = *base_test.get_or_insert_with(|| test_sums(p, &cur.residual));
        cur.base_test = base;
        cur.horizon = horizon_errors(p, &state);
        // The total grows by a round's candidates as rounds start.
        let total = done + remaining.len();
        let mut candidates = Vec::new();
        for kind in remaining {
            progress(done, total, kind.name());
            candidates.push(evaluate(p, &state, &cur, kind, rules));
            done += 1;
        }
        progress(done, total, "");
        let mut best = candidates
            .iter()
            .filter(|c| c.significant)
            .min_by(|a, b| a.delta_bic_test.total_cmp(&b.delta_bic_test))
            .cloned();
        // A delay and a first-order lag agree to first order in frequency (phase ω·d): a pure delay
        // is named over a significant lag only when its score is clearly better.
        if let Some(b) = best.as_ref().filter(|b| b.kind == EffectKind::Latency) {
            let lag = candidates
                .iter()
                .find(|c| c.kind == EffectKind::ActuatorLag && c.significant);
            if let Some(lag) = lag.filter(|l| b.delta_bic_test > DELAY_MARGIN * l.delta_bic_test) {
                best = Some(lag.clone());
            }
        }
        // channel_response fits a delay, a lag and a gain per channel: it is named over a
        // significant latency or actuator_lag only when its score is clearly better (the simpler
        // effect explains as much otherwise).
        if let Some(b) = best.as_ref().filter(|b| b.kind == EffectKind::ChannelResponse) {
            let simpler = candidates
                .iter()
                .filter(|c| matches!(c.kind, EffectKind::Latency | EffectKind::ActuatorLag) && c.significant)
                .min_by(|a, b| a.delta_bic_test.total_cmp(&b.delta_bic_test));
            if let Some(s) = simpler.filter(|s| b.delta_bic_test > DELAY_MARGIN * s.delta_bic_test) {
                best = Some(s.clone());
            }
        }
        let full = state.named.len() + 1 >= rules.max_effects + data_effects;
        rounds.push(Round {
            candidates,
            named: best.as_ref().map(|c| c.kind),
        });
        match best {
            Some(c) => {
                install(p, &mut state, &c);
                if full {
                    break;
                }
            }
            None => break,
        }
    }
    (state, rounds)
}
