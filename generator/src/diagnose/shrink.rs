//! How far the gap shrinks: the base model and the model with the named effects, on held-out data,
//! per state and overall — one-step derivative (vx..yaw_rate, the filtered residual of
//! [`super::residuals`], but stepping the corrected model exactly) and free runs over the horizon
//! from every sample (all 12 states, yaw errors wrapped), RMSE and d₁ (`crate::metrics`).

use super::augmented::Augmented;
use super::catalogue::CHANNELS;
use super::data::SegData;
use super::problem::{Problem, State};
use super::residuals::{filter, ResidualKind};
use crate::evaluate::pooled::{MeanBook, Stat};
use crate::evaluate::{wrap_angle, DIVERGENCE_BOUND};
use crate::logs::{on_ground, run_touches_ground};
use crate::logs::{STATE_COLUMNS, YAW};
use crate::metrics::Metrics;
use serde::Serialize;

/// Predictions pooled over segments, streamed into running sums as they are made, never stored
/// (a horizon of H samples makes H predictions per sample): `evaluate`'s [`Stat`]s, which give
/// `metrics::compare`'s figures on the pooled rows to the bit, d₁ about a provisional mean of the
/// observations (see [`side`]).
pub(crate) struct Pool {
    /// No model run: every one-step prediction finite and every free run complete, to find the
    /// pooled observations' means (they depend on the data alone unless something diverges).
    observe: bool,
    book: MeanBook,
    one: Stat,
    hor: Stat,
    end: Stat,
    step_sq: Vec<f64>,
    step_n: Vec<usize>,
    runs: usize,
    diverged: usize,
}

/// The figures of the rows `feed` adds to a pool (it is called up to three times, adding the same
/// segments with the same models each time): a pass without free runs finds the pooled
/// observations' means, a pass with them streams the predictions, and only where a prediction
/// diverged (the means were then not the pooled rows') a third pass with the exact means. The
/// figures are those of `metrics::compare` on the stored rows, to the bit.
pub(crate) fn side(mut feed: impl FnMut(&mut Pool)) -> Side {
    let mut observed = Pool::new(true, Vec::new());
    feed(&mut observed);
    observed.side();
    let mut pool = Pool::new(false, observed.book.found());
    feed(&mut pool);
    let side = pool.side();
    if pool.book.exact() {
        return side;
    }
    let mut again = Pool::new(false, pool.book.found());
    feed(&mut again);
    again.side()
}

fn finite(x: &[f64]) -> bool {
    x.iter().all(|v| v.is_finite() && v.abs() <= DIVERGENCE_BOUND)
}

/// The filtered one-step residual of the augmented model on `seg` (interior samples).
pub(crate) fn one_step_residual(aug: &Augmented, seg: &SegData) -> Vec<[f64; 6]> {
    let n = seg.len();
    let seen = aug.seen_inputs(seg);
    let m = aug.substeps(seg.dt, seg.substeps);
    if seg.residual == ResidualKind::Pointwise {
        return seg
            .interior()
            .zip(&seg.dx)
            .map(|(k, d)| {
                let f = aug.f(&seg.x[k], &seen.s[k], seg.flight_time(k), &seen.v[k]);
                std::array::from_fn(|c| d[c] - f[6 + c])
            })
            .collect();
    }
    let mut e = vec![[0.0; 6]; n];
    for k in 0..n - 1 {
        let (next, _) = aug.step(&seg.x[k], &seen.s[k], seg.flight_time(k), &seen.v[k], seg.dt, m);
        e[k] = std::array::from_fn(|c| (seg.x[k + 1][6 + c] - next[6 + c]) / seg.dt);
    }
    filter(&seg.kernel, &e, n)
}

/// A free run of `len` samples from row k: the predictions for rows k+1..=k+len (fewer if it
/// diverged).
pub(crate) fn run(
    aug: &Augmented,
    seg: &SegData,
    seen: &super::augmented::SeenInputs,
    k: usize,
    len: usize,
) -> Vec<[f64; 12]> {
    let m = aug.substeps(seg.dt, seg.substeps);
    let (mut x, mut s) = (seg.x[k], seen.s[k]);
    let mut out = Vec::with_capacity(len);
    for j in 0..len {
        let (nx, ns) = aug.step(&x, &s, seg.flight_time(k + j), &seen.v[k + j], seg.dt, m);
        if !finite(&nx) {
            break;
        }
        out.push(nx);
        x = nx;
        s = ns;
    }
    out
}

pub(crate) fn wrapped(p: &[f64; 12], o: &[f64; 12]) -> [f64; 12] {
    let mut p = *p;
    p[YAW] = o[YAW] + wrap_angle(p[YAW] - o[YAW]);
    p
}

/// The base model and the model `state` describes, pooled over the test segments s of every test
/// fit, with that fit's parameters, their input delays rounded to whole samples of each segment as
/// `uavgen evaluate` runs the model files (so that it reproduces these figures; the fitted delays
/// themselves keep their fraction of a sample); `seg(s, destaled)` gives the data of segment s, raw or with
/// stale rows interpolated (None: left out). The model with the effects runs on the data under the
/// stale policy (`state.destale`); the base model on the same data (`before_raw` false: the figures
/// `uavgen evaluate` reproduces), or on the raw data (`before_raw` true: the self-check's gap,
/// which the stale rows opened, on the noise-free copies).
pub(crate) fn pools<'d>(
    p: &Problem,
    state: &State,
    before_raw: bool,
    seg: impl Fn(usize, bool) -> Option<&'d SegData<'d>>,
) -> (Side, Side) {
    let plain = Augmented::plain(p.base, p.ctx);
    let base_variant = state.destale && !before_raw;
    let before = side(|pool| {
        for i in p.test_fits() {
            for &s in &p.fits[i].test {
                if let (Some(raw), Some(_)) = (seg(s, base_variant), seg(s, state.destale)) {
                    pool.add(&whole_samples(&plain, raw.dt), raw, p.options.horizon);
                }
            }
        }
    });
    let after = side(|pool| {
        for i in p.test_fits() {
            let aug = p.augmented(state, i);
            for &s in &p.fits[i].test {
                if let (Some(_), Some(variant)) = (seg(s, base_variant), seg(s, state.destale)) {
                    pool.add(&whole_samples(&aug, variant.dt), variant, p.options.horizon);
                }
            }
        }
    });
    (before, after)
}

/// `a` with its delays rounded to whole samples of `dt` (`InputTransform::whole_samples`).
fn whole_samples<'a>(a: &Augmented<'a>, dt: f64) -> Augmented<'a> {
    Augmented {
        base: a.base,
        ctx: a.ctx,
        linear: a.linear.clone(),
        transform: a.transform.whole_samples(dt),
    }
}

impl Pool {
    fn new(observe: bool, means: Vec<Vec<f64>>) -> Self {
        let mut book = MeanBook::with_means(means);
        let (one, hor, end) = (book.stat(CHANNELS.len()), book.stat(12), book.stat(12));
        Self {
            observe,
            book,
            one,
            hor,
            end,
            step_sq: Vec::new(),
            step_n: Vec::new(),
            runs: 0,
            diverged: 0,
        }
    }

    pub fn add(&mut self, aug: &Augmented, seg: &SegData, horizon: usize) {
        let r = one_step_residual(aug, seg);
        for ((obs, res), airborne) in seg.dx.iter().zip(&r).zip(&seg.airborne) {
            let pred: [f64; 6] = std::array::from_fn(|c| obs[c] - res[c]);
            if *airborne && finite(&pred) {
                self.one.push(&pred, obs, None);
            }
        }
        if self.step_sq.len() < horizon {
            self.step_sq.resize(horizon, 0.0);
            self.step_n.resize(horizon, 0);
        }
        let n = seg.len();
        let ground = on_ground(&seg.x);
        if self.observe {
            for k in 0..n.saturating_sub(horizon) {
                if run_touches_ground(&ground, k, horizon) {
                    continue;
                }
                for o in &seg.x[k + 1..=k + horizon] {
                    self.hor.push(o, o, None);
                }
                if horizon > 0 {
                    self.end.push(&seg.x[k + horizon], &seg.x[k + horizon], None);
                }
            }
            return;
        }
        let seen = aug.seen_inputs(seg);
        for k in 0..n.saturating_sub(horizon) {
            if run_touches_ground(&ground, k, horizon) {
                continue;
            }
            self.runs += 1;
            let pred = run(aug, seg, &seen, k, horizon);
            for (j, p) in pred.iter().enumerate() {
                let o = &seg.x[k + j + 1];
                let p = wrapped(p, o);
                self.step_sq[j] += (0..12).map(|i| (p[i] - o[i]).powi(2)).sum::<f64>();
                self.step_n[j] += 1;
                self.hor.push(&p, o, None);
            }
            if pred.len() == horizon {
                let o = &seg.x[k + horizon];
                self.end.push(&wrapped(&pred[horizon - 1], o), o, None);
            } else {
                self.diverged += 1;
            }
        }
    }

    fn side(&mut self) -> Side {
        let channels: Vec<String> = CHANNELS.iter().map(|c| c.to_string()).collect();
        let states: Vec<String> = STATE_COLUMNS.iter().map(|c| c.to_string()).collect();
        let book = &mut self.book;
        Side {
            one_step: self.one.metrics(&channels, book).ok().flatten(),
            horizon: self.hor.metrics(&states, book).ok().flatten(),
            horizon_end: self.end.metrics(&states, book).ok().flatten(),
            rmse_by_step: self
                .step_sq
                .iter()
                .zip(&self.step_n)
                .map(|(s, &n)| (n > 0).then(|| (s / (12 * n) as f64).sqrt()))
                .collect(),
            horizon_runs: self.runs,
            horizon_diverged: self.diverged,
        }
    }
}

/// One model's figures on the held-out data.
#[derive(Clone, Debug, Serialize)]
pub struct Side {
    /// One-step derivative, vx..yaw_rate (null without samples).
    pub one_step: Option<Metrics>,
    /// Free runs over the horizon from every sample, all steps pooled, 12 states.
    pub horizon: Option<Metrics>,
    /// The same at the last step of the horizon only.
    pub horizon_end: Option<Metrics>,
    /// Overall RMSE (12 states pooled) at each step 1..=horizon.
    pub rmse_by_step: Vec<Option<f64>>,
    pub horizon_runs: usize,
    pub horizon_diverged: usize,
}

/// One state before and after.
#[derive(Clone, Debug, Serialize)]
pub struct StateShrink {
    pub state: String,
    /// One-step derivative RMSE and d₁ (null for the kinematic states x … yaw).
    pub one_step_rmse_before: Option<f64>,
    pub one_step_rmse_after: Option<f64>,
    pub one_step_d1_before: Option<f64>,
    pub one_step_d1_after: Option<f64>,
    /// Horizon free-run RMSE and d₁, all steps pooled.
    pub horizon_rmse_before: Option<f64>,
    pub horizon_rmse_after: Option<f64>,
    pub horizon_d1_before: Option<f64>,
    pub horizon_d1_after: Option<f64>,
}

/// The closed-loop comparison through `uavgen track` on a plant file: a hook, not yet wired.
#[derive(Clone, Debug, Serialize)]
pub struct ClosedLoop {
    /// `"not run"` (no `--plant`), `"measured"`, or `"failed"` (the note says why).
    pub status: String,
    /// The `--plant` file given, if any.
    pub plant: Option<String>,
    pub note: String,
    /// `"better"`, `"no change"` or `"worse"`: how the corrected model flies against the base
    /// (`track::compare::judge`); `"worse"` means the corrections are not recommended for closed
    /// loop. `None` unless measured.
    pub verdict: Option<String>,
    /// Per trajectory: the tracking error with the base and with the corrected model.
    pub runs: Vec<ClosedLoopRun>,
}

/// One trajectory flown with the base and with the corrected model (`uavgen track`, generated
/// solver through the runtime, the plant's seed 1, from the paper's start state).
#[derive(Clone, Debug, Serialize)]
pub struct ClosedLoopRun {
    pub trajectory: String,
    pub seconds: f64,
    /// Overall position RMSE / MAE / d₁ (x, y, z), whole run.
    pub rmse_before: f64,
    pub rmse_after: f64,
    pub mae_before: f64,
    pub mae_after: f64,
    pub d1_before: f64,
    pub d1_after: f64,
    /// Inputs outside the bounds (must be 0), base and corrected.
    pub out_of_bounds_before: usize,
    pub out_of_bounds_after: usize,
    /// `uavgen track`'s verdict of each run (default thresholds: docs/track.md).
    pub verdict_before: crate::track::Verdict,
    pub verdict_after: crate::track::Verdict,
}

/// The gap before and after the named effects.
#[derive(Clone, Debug, Serialize)]
pub struct Shrink {
    /// Which data: `"held-out logs"` or the cross-validation folds.
    pub data: String,
    /// The effects added (the verdict; empty for `none`: then after = before).
    pub effects: Vec<String>,
    pub horizon: usize,
    pub before: Side,
    pub after: Side,
    pub per_state: Vec<StateShrink>,
    pub closed_loop: ClosedLoop,
}

impl Shrink {
    pub fn new(
        data: String,
        effects: Vec<String>,
        horizon: usize,
        before: Side,
        after: Side,
        closed_loop: ClosedLoop,
    ) -> Self {
        let pick = |m: &Option<Metrics>, name: &str, f: fn(&Metrics, usize) -> f64| {
            m.as_ref()
                .and_then(|m| m.names.iter().position(|n| n == name).map(|i| f(m, i)))
        };
        let rmse = |m: &Metrics, i: usize| m.rmse[i];
        let d1 = |m: &Metrics, i: usize| m.d1[i];
        let per_state = STATE_COLUMNS
            .iter()
            .map(|&s| StateShrink {
                state: s.to_string(),
                one_step_rmse_before: pick(&before.one_step, s, rmse),
                one_step_rmse_after: pick(&after.one_step, s, rmse),
                one_step_d1_before: pick(&before.one_step, s, d1),
                one_step_d1_after: pick(&after.one_step, s, d1),
                horizon_rmse_before: pick(&before.horizon, s, rmse),
                horizon_rmse_after: pick(&after.horizon, s, rmse),
                horizon_d1_before: pick(&before.horizon, s, d1),
                horizon_d1_after: pick(&after.horizon, s, d1),
            })
            .collect();
        Self {
            data,
            effects,
            horizon,
            before,
            after,
            per_state,
            closed_loop,
        }
    }
}
