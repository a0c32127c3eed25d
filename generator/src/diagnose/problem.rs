//! What the selection works on: the fits (training and held-out segments), the state of the
//! named effects, the current designs and residuals, and the joint linear least squares. Shared by
//! the candidates ([`super::candidate`], [`super::loop_fit`], [`super::response_fit`]), the horizon
//! rule and the selection ([`super::select`]); it depends on none of them.

use super::augmented::Augmented;
use super::catalogue::inputs::InputTransform;
use super::catalogue::linear::{linear_parameters, Context};
use super::catalogue::EffectKind;
use super::data::Prepared;
use super::data::SegData;
use super::design::{seen_f, Design, SegBase, CHUNK};
use super::fcache::SeenCache;
use super::fit::Normal;
use super::fit::MAX_LAG;
use super::residuals::Base;
use super::score::{sums_masked, taus, Sums};
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
    pub data: &'a Prepared<'a>,
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
    pub fn seen_f(&self, seg: &SegData, tr: &InputTransform) -> Vec<[f64; 6]> {
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

/// The current model's fitting problem per segment ([`SegBase`]: r⁰ and f′'s v̇ under the
/// state's transform; the linear columns and the residuals are computed from it when needed),
/// and what every candidate of a round is scored against.
pub(crate) struct Current<'d> {
    pub segs: Vec<SegBase<'d>>,
    /// The named linear effects and, per fit, their parameters (the state's).
    pub linear: Vec<EffectKind>,
    pub theta: Vec<Vec<f64>>,
    /// Sums and τ of the current residuals ([`before`]; default outside the selection rounds).
    pub before: Before,
    /// The base model's held-out sums (of the first round), the reference of the reduction rule.
    pub base_test: Sums,
    /// The held-out horizon errors of the model so far ([`super::horizon_rule`]; empty outside
    /// the selection rounds).
    pub horizon: HorizonErrors,
}

/// The current residuals, summed as the candidates are scored against them.
#[derive(Clone, Debug, Default)]
pub(crate) struct Before {
    /// Per fit: its training sums (masked samples).
    pub fit_train: Vec<Sums>,
    /// The final fit's training τ per channel (lags up to [`MAX_LAG`]).
    pub train_tau: [f64; 6],
    /// The test fits' held-out sums (each fit's, added in fit order) and τ per channel (lags up
    /// to the Savitzky-Golay window).
    pub test: Sums,
    pub test_tau: [f64; 6],
}

impl Before {
    /// The final fit's training sums.
    pub fn train(&self) -> Sums {
        *self.fit_train.last().expect("the sums of every fit")
    }
}

impl<'d> Current<'d> {
    /// Fit `i`'s residual (the named linear corrections with its parameters) per segment.
    pub fn residual(&self, p: &Problem, i: usize) -> Vec<Vec<[f64; 6]>> {
        self.segs
            .iter()
            .map(|b| b.residual(&p.ctx, &self.linear, &self.theta[i]))
            .collect()
    }

    /// Each fit's training sums of its residual.
    pub fn train_sums(&self, p: &Problem) -> Vec<Sums> {
        p.fits
            .iter()
            .enumerate()
            .map(|(i, fold)| {
                let mut sums = Sums::default();
                for &s in &fold.train {
                    self.segs[s].add_sums(&p.ctx, &self.linear, &self.theta[i], &p.mask[s], &mut sums);
                }
                sums
            })
            .collect()
    }

    /// The chunks of segment `s`'s design with the columns of `kinds` ([`SegBase::chunks`]).
    pub fn chunks(&self, p: &Problem, s: usize, kinds: &[EffectKind], f: &mut dyn FnMut(usize, &Design)) {
        self.segs[s].chunks(&p.ctx, kinds, CHUNK, f);
    }
}

pub(crate) fn current<'d>(p: &Problem<'d>, state: &State) -> Current<'d> {
    let segs = p.data.variant(state.destale);
    Current {
        segs: segs
            .iter()
            .map(|s| SegBase::under(s, &state.transform, || seen_f(s, p.base, &state.transform)))
            .collect(),
        linear: state.linear.clone(),
        theta: state.theta.clone(),
        before: Before::default(),
        base_test: Sums::default(),
        horizon: HorizonErrors::default(),
    }
}

/// The sums and τ of the current residuals ([`Before`]), one fit's residual at a time.
pub(crate) fn before(p: &Problem, cur: &Current) -> Before {
    let fin = p.final_fit();
    let all = [0, 1, 2, 3, 4, 5];
    let mut out = Before::default();
    let tests = p.test_fits();
    let mut test_parts: Vec<Vec<[f64; 6]>> = Vec::new();
    for (i, fold) in p.fits.iter().enumerate() {
        let mut res = cur.residual(p, i);
        out.fit_train.push(sums_masked(&res, &fold.train, &p.mask));
        if i == fin {
            let parts: Vec<&[[f64; 6]]> = fold.train.iter().map(|&t| res[t].as_slice()).collect();
            out.train_tau = taus(&parts, &all, MAX_LAG);
        }
        if tests.contains(&i) {
            out.test.add(&sums_masked(&res, &fold.test, &p.mask));
            test_parts.extend(fold.test.iter().map(|&t| std::mem::take(&mut res[t])));
        }
    }
    let parts: Vec<&[[f64; 6]]> = test_parts.iter().map(Vec::as_slice).collect();
    out.test_tau = taus(&parts, &all, p.options.savgol.window);
    out
}

/// A candidate's residual summed as [`super::scored::finish`] scores it: the final fit's training
/// sums and each test fit's held-out sums, over the masked samples, segments in order.
#[derive(Clone, Debug)]
pub(crate) struct AfterSums {
    pub train: Sums,
    /// Per fit (those that are not test fits stay empty).
    pub test: Vec<Sums>,
    role: Vec<Vec<Role>>,
    fin: usize,
}

impl AfterSums {
    pub fn new(p: &Problem, segments: usize) -> Self {
        Self {
            train: Sums::default(),
            test: vec![Sums::default(); p.fits.len()],
            role: roles(p, segments),
            fin: p.final_fit(),
        }
    }

    /// Whether fit `i`'s residual on segment `s` is counted.
    pub fn wants(&self, i: usize, s: usize) -> bool {
        match self.role[i][s] {
            Role::Train => i == self.fin,
            Role::Test => true,
            Role::None => false,
        }
    }

    /// Add fit `i`'s residual `res` of segment `s`, interior samples from `k0` (pieces of a
    /// segment in order, segments in order).
    pub fn add(&mut self, p: &Problem, i: usize, s: usize, k0: usize, res: &[[f64; 6]]) {
        let mask = &p.mask[s][k0..k0 + res.len()];
        match self.role[i][s] {
            Role::Train if i == self.fin => self.train.push_masked(res, mask),
            Role::Test => self.test[i].push_masked(res, mask),
            _ => {}
        }
    }
}

/// The role of each segment in each fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Role {
    None,
    Train,
    Test,
}

pub(crate) fn roles(p: &Problem, n: usize) -> Vec<Vec<Role>> {
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

/// Weighted least squares of the linear `kinds` on the vx vy vz residuals r⁰ of `segs` (per
/// segment; [`SegBase::unused`] where no fit trains), for each of the training sets `trains`
/// (ascending segment indices) at once. Weights 1/MSE_c per channel, from `start` (each fit's
/// training sums before), then once more from the fit's own residual. Returns per training set
/// θ, the unscaled covariance and the weights of the last pass. The columns are computed a chunk
/// at a time and summed into the normal equations in the order of the samples.
pub(crate) fn fit_linear(
    p: &Problem,
    segs: &[SegBase],
    trains: &[&[usize]],
    kinds: &[EffectKind],
    start: &[Sums],
) -> Vec<(Vec<f64>, nalgebra::DMatrix<f64>, [f64; 3])> {
    fit_linear_chunked(&p.ctx, &p.mask, segs, trains, kinds, start, CHUNK)
}

/// [`fit_linear`] with columns computed `chunk` samples at a time (the result does not depend on it).
pub(crate) fn fit_linear_chunked(
    ctx: &Context,
    mask: &[Vec<bool>],
    segs: &[SegBase],
    trains: &[&[usize]],
    kinds: &[EffectKind],
    start: &[Sums],
    chunk: usize,
) -> Vec<(Vec<f64>, nalgebra::DMatrix<f64>, [f64; 3])> {
    let p: usize = kinds.iter().map(|k| super::catalogue::linear::columns(*k)).sum();
    let weights_of = |s: &Sums| -> [f64; 3] {
        let mse = s.mse();
        std::array::from_fn(|c| if mse[c] > 0.0 { 1.0 / mse[c] } else { 1.0 })
    };
    debug_assert!(trains.iter().all(|t| t.windows(2).all(|w| w[0] < w[1])));
    // users[s]: the training sets that hold segment s.
    let users: Vec<Vec<usize>> = (0..segs.len())
        .map(|s| (0..trains.len()).filter(|&i| trains[i].contains(&s)).collect())
        .collect();
    let mut w: Vec<[f64; 3]> = start.iter().map(weights_of).collect();
    let mut out: Vec<(Vec<f64>, nalgebra::DMatrix<f64>)> =
        vec![(vec![0.0; p], nalgebra::DMatrix::zeros(p, p)); trains.len()];
    for pass in 0..2 {
        let mut ne: Vec<Normal> = (0..trains.len()).map(|_| Normal::new(p)).collect();
        let mut row = vec![0.0; p];
        for (s, base) in segs.iter().enumerate() {
            if users[s].is_empty() {
                continue;
            }
            base.chunks(ctx, kinds, chunk, |k0, d| {
                let cols: Vec<&Vec<[f64; 3]>> = kinds.iter().flat_map(|k| d.columns_of(*k)).collect();
                for &i in &users[s] {
                    for (k, r) in d.r0.iter().enumerate() {
                        if !mask[s][k0 + k] {
                            continue;
                        }
                        for c in 0..3 {
                            for (q, col) in cols.iter().enumerate() {
                                row[q] = col[k][c];
                            }
                            ne[i].add(&row, r[c], w[i][c]);
                        }
                    }
                }
            });
        }
        out = ne.iter().map(Normal::solve).collect();
        if pass == 0 {
            for (i, train) in trains.iter().enumerate() {
                let mut sums = Sums::default();
                for &s in train.iter() {
                    segs[s].add_sums(ctx, kinds, &out[i].0, &mask[s], &mut sums);
                }
                w[i] = weights_of(&sums);
            }
        }
    }
    out.into_iter()
        .zip(w)
        .map(|((theta, cov), w)| (theta, cov, w))
        .collect()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::catalogue::linear::{columns, regressors, Sample};
    use crate::diagnose::design::vertical_only;
    use crate::diagnose::residuals::{filter, ResidualKind};
    use crate::identify::preprocess::SavGol;

    /// A 150-row log of smooth manoeuvres (airborne but for a few rows near the ground) and the
    /// M100 SINDy model.
    fn setup() -> (Base, Vec<crate::logs::FlightLog>) {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/sindy_m100.json");
        let text = std::fs::read_to_string(&path).unwrap();
        let model = crate::model::parse(&text, "sindy_m100.json").unwrap();
        let base = Base::new(&model, None, None);
        let mut csv = String::from(
            "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate\n",
        );
        for k in 0..150 {
            let t = k as f64 * 0.05;
            let s = |w: f64, a: f64| a * (w * t).sin();
            let z = if (40..44).contains(&k) { 0.0 } else { 2.0 + s(0.7, 0.5) };
            let row = [
                t,
                s(0.3, 2.0),
                s(0.2, 1.0),
                z,
                s(1.1, 0.1),
                s(0.9, 0.12),
                s(0.4, 0.5),
                s(0.3, 0.6) + 0.5,
                s(0.2, 0.2) - 0.3,
                s(0.7, 0.35),
                s(1.1, 0.11),
                s(0.9, 0.1),
                s(0.4, 0.2),
                s(0.8, 0.4),
                s(1.3, 0.1),
                s(1.0, 0.1),
                s(0.5, 0.3),
            ];
            let line: Vec<String> = row.iter().map(|v| format!("{v}")).collect();
            csv.push_str(&line.join(","));
            csv.push('\n');
        }
        let log = crate::logs::parse_log(&csv, "chunks.csv").unwrap();
        (base, vec![log])
    }

    /// The linear columns, residuals, sums and normal equations computed `CHUNK` samples at a time
    /// are those of the whole segment's columns computed directly, to the bit, for chunks of 1, 7
    /// and more than the samples.
    #[test]
    fn chunked_designs_equal_the_direct_columns() {
        let (base, logs) = setup();
        let savgol = SavGol { window: 9, order: 3 };
        let data = super::super::data::prepare(&base, &savgol, ResidualKind::Matched, &logs, &[], 1).unwrap();
        let seg = &data.raw[0];
        let ctx = Context {
            gravity: base.gravity,
            rotor_radius: 0.5,
        };
        let mut transform = InputTransform::of_base(&base);
        transform.delay[0] = 0.07;
        transform.lag[1] = Some(0.1);
        let fs = seen_f(seg, &base, &transform);
        let kinds: Vec<EffectKind> = vec![
            EffectKind::LinearDrag,
            EffectKind::QuadraticDrag,
            EffectKind::ForceBias,
            EffectKind::ThrustGain,
            EffectKind::ThrustDecay,
            EffectKind::GroundEffect,
        ];
        let p: usize = kinds.iter().map(|k| columns(*k)).sum();
        let theta: Vec<f64> = (0..p)
            .map(|i| 0.01 * (i as f64 + 1.0) * if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let sb = SegBase::new(seg, &fs);
        let n = seg.len();
        let interior = n - 2 * seg.h;
        assert!(seg.airborne.iter().any(|a| !a), "some samples are masked");
        // Direct: every column over the whole segment, then r = r⁰ − Σ θ col.
        let mut direct: Vec<Vec<[f64; 3]>> = Vec::new();
        for &kind in &kinds {
            let q = columns(kind);
            let mut point = vec![vec![[0.0; 3]; n]; q];
            let mut buf = [[0.0; 3]; 3];
            for m in 0..n {
                let s = Sample {
                    x: &seg.x[m],
                    base_acc: [fs[m][0], fs[m][1], fs[m][2]],
                    flight_time: seg.flight_time(m),
                };
                regressors(kind, &s, &ctx, &mut buf[..q]);
                if vertical_only(kind) {
                    for b in &mut buf[..q] {
                        b[0] = 0.0;
                        b[1] = 0.0;
                    }
                }
                for i in 0..q {
                    point[i][m] = buf[i];
                }
            }
            direct.extend(point.iter().map(|c| filter(&seg.kernel, c, n)));
        }
        let mut r_direct: Vec<[f64; 6]> = sb.r0().to_vec();
        for (col, th) in direct.iter().zip(&theta) {
            for (r, c) in r_direct.iter_mut().zip(col) {
                for ch in 0..3 {
                    r[ch] -= th * c[ch];
                }
            }
        }
        let mut sums_direct = Sums::default();
        sums_direct.push_masked(&r_direct, &seg.airborne);
        let w = [2.0, 3.0, 0.5];
        let mask = vec![seg.airborne.clone()];
        let start = Sums {
            sse: [1.0 / w[0], 1.0 / w[1], 1.0 / w[2], 1.0, 1.0, 1.0],
            n: 1,
        };
        let mut fits = Vec::new();
        for chunk in [1, 7, interior + 5] {
            let mut cols: Vec<Vec<[f64; 3]>> = vec![Vec::new(); p];
            let mut r = Vec::new();
            sb.chunks(&ctx, &kinds, chunk, |k0, d| {
                assert_eq!(k0, r.len());
                let flat: Vec<&Vec<[f64; 3]>> = kinds.iter().flat_map(|k| d.columns_of(*k)).collect();
                for (i, c) in flat.iter().enumerate() {
                    cols[i].extend_from_slice(c);
                }
                r.extend(d.residual(&kinds, &theta));
            });
            assert_eq!(cols, direct, "chunk {chunk}: columns");
            assert_eq!(r, r_direct, "chunk {chunk}: residual");
            let fit = fit_linear_chunked(&ctx, &mask, std::slice::from_ref(&sb), &[&[0]], &kinds, &[start], chunk);
            fits.push(fit.into_iter().next().unwrap());
        }
        let mut sums = Sums::default();
        sb.add_sums(&ctx, &kinds, &theta, &seg.airborne, &mut sums);
        assert_eq!(sums, sums_direct);
        assert_eq!(sb.residual(&ctx, &kinds, &theta), r_direct);
        // Every chunk size gives the same two-pass weighted fit: the direct normal equations'
        // solution with the weights of the last pass.
        assert!(fits
            .windows(2)
            .all(|f| f[0].0 == f[1].0 && f[0].1 == f[1].1 && f[0].2 == f[1].2));
        let mut ne1 = Normal::new(p);
        let w1 = fits[0].2;
        for k in 0..interior {
            if seg.airborne[k] {
                for c in 0..3 {
                    let row: Vec<f64> = direct.iter().map(|col| col[k][c]).collect();
                    ne1.add(&row, sb.r0()[k][c], w1[c]);
                }
            }
        }
        assert_eq!(ne1.solve().0, fits[0].0);
    }
}
