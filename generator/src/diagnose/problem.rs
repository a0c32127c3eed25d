//! What the selection works on: the fits (training and held-out segments), the state of the
//! named effects, the current designs and residuals, and the joint linear least squares. Shared by
//! the candidates ([`super::candidate`], [`super::loop_fit`], [`super::response_fit`]), the horizon
//! rule and the selection ([`super::select`]); it depends on none of them.

use super::augmented::Augmented;
use super::catalogue::inputs::InputTransform;
use super::catalogue::linear::{linear_kinds, linear_parameters, Context};
use super::catalogue::EffectKind;
use super::data::Prepared;
use super::data::SegData;
use super::design::seen_f;
use super::design::{design, Design};
use super::fcache::SeenCache;
use super::fit::Normal;
use super::residuals::Base;
use super::score::{sums_masked, Sums};
use super::DiagnoseOptions;
use std::cell::RefCell;
use std::ops::Range;

/// The shortest span of `latency`'s delay scan, s (10 samples at 30 Hz; twice the longest
/// command delay of the aircraft classes the project has data of, m100_like's 0.176 s).
pub const MIN_LATENCY_SCAN: f64 = 1.0 / 3.0;

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
    /// f′ of the scan under way ([`super::fcache`]; set by [`Problem::scope`]).
    pub seen: RefCell<Option<SeenCache>>,
}

/// Clears [`Problem::seen`] when the scan it was set for ends.
pub(crate) struct Scope<'p, 'a> {
    p: &'p Problem<'a>,
}

impl Drop for Scope<'_, '_> {
    fn drop(&mut self) {
        self.p.seen.replace(None);
    }
}

impl<'a> Problem<'a> {
    /// The median sample period of the segments, s.
    pub fn dt(&self) -> f64 {
        let mut dts: Vec<f64> = self.data.raw.iter().map(|s| s.dt).collect();
        dts.sort_by(f64::total_cmp);
        dts.get(dts.len() / 2).copied().unwrap_or(0.0)
    }

    /// The longest delay `latency` scans, s: `max_delay_samples` samples, but at least
    /// [`MIN_LATENCY_SCAN`] (so that a fast log is scanned as far in time as a 30 Hz one).
    pub fn max_delay(&self) -> f64 {
        let dt = self.dt();
        (self.options.max_delay_samples * dt).max(MIN_LATENCY_SCAN)
    }

    /// The whole-sample step of the coarse delay scan: the scan spans [`Problem::max_delay`] in
    /// at most `max_delay_samples` steps (1 sample when that reaches it, e.g. at 30 Hz).
    pub fn delay_step_samples(&self) -> f64 {
        let dt = self.dt();
        if dt <= 0.0 {
            return 1.0;
        }
        (self.max_delay() / dt / self.options.max_delay_samples.max(1.0) - 1e-9)
            .ceil()
            .max(1.0)
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

    /// f′ of `seg` under `tr` ([`seen_f`]), from the scan's cache when one is set.
    pub fn seen_f(&self, seg: &SegData, tr: &InputTransform) -> Vec<[f64; 12]> {
        match &*self.seen.borrow() {
            Some(c) => c.seen_f(seg, self.base, tr),
            None => seen_f(seg, self.base, tr),
        }
    }

    /// Cache f′ for a scan of `state`'s transform varied in `input` (None: only acceleration
    /// lags vary; `row_lag`: an acceleration row's lag is scanned) until the returned guard drops.
    pub fn scope(&self, state: &State, input: Option<usize>, row_lag: bool) -> Scope<'_, 'a> {
        let segs: Vec<&SegData> = self.data.variant(state.destale).iter().collect();
        let ends = row_lag || state.transform.accel_lag.iter().any(Option::is_some);
        let cache = SeenCache::new(self.base, &segs, &state.transform, input, ends);
        self.seen.replace(cache);
        Scope { p: self }
    }

    /// The model `state` describes with the parameters of fit `i`, to step exactly.
    pub fn augmented(&self, state: &State, i: usize) -> Augmented<'_> {
        let (linear, _) = linear_parameters(&state.linear, &state.theta[i]);
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

/// Pooled horizon errors of one model on the held-out data.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct HorizonErrors {
    pub sse: [f64; 12],
    pub n: usize,
    pub runs: usize,
    pub diverged: usize,
}

impl HorizonErrors {
    /// R of `after` against `self` (None without samples).
    pub fn ratio(&self, after: &HorizonErrors) -> Option<f64> {
        if self.n == 0 || after.n == 0 {
            return None;
        }
        let r: Vec<f64> = (0..12)
            .filter(|&i| self.sse[i] > 0.0)
            .map(|i| (after.sse[i] / after.n as f64) / (self.sse[i] / self.n as f64))
            .collect();
        (!r.is_empty()).then(|| r.iter().sum::<f64>() / r.len() as f64)
    }

    /// The rule — not worse on average over the states, and no more diverged runs: why `after`
    /// fails it (None when it passes).
    pub fn objection(&self, after: &HorizonErrors) -> Option<String> {
        if after.diverged > self.diverged {
            return Some(format!(
                "{} held-out free runs over the horizon diverge with it ({} without)",
                after.diverged, self.diverged
            ));
        }
        match self.ratio(after) {
            Some(r) if r > 1.0 => Some(format!(
                "it makes the held-out free runs over the horizon worse (mean MSE ratio over the 12 states {r:.3})"
            )),
            _ => None,
        }
    }
}
