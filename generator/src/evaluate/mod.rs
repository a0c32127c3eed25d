//! Evaluation of a model against flight logs: three prediction kinds, reported separately
//! (never mixed). See docs/evaluate.md.
//!
//! 1. **One-step**: (a) the derivative f(x_k, u_k) against the Savitzky-Golay derivative of
//!    the log (dynamic rows vx..yaw_rate only), (b) the next sample F(x_k, u_k) against x_{k+1}
//!    (all 12 states), F = RK4 with M substeps over the segment's median Δt.
//! 2. **Horizon free run**: from every sample k with k + H in the segment, start at the
//!    measured x_k, apply the logged inputs (zero-order hold) for H samples, compare the H
//!    predictions with the measured states (pooled), and separately at step H.
//! 3. **Whole-flight free run**: each segment from its first sample to its end.
//!
//! A prediction that is not finite or exceeds [`DIVERGENCE_BOUND`] in magnitude ends its run
//! (reported as `diverged_at`); metrics are computed over the finite part. Yaw errors are
//! wrapped to (−π, π].
//!
//! A model with `corrections` is run on its full state (the extra states start from the log, see
//! `inputs.rs`) and sees each input delayed by its latency; it is scored on the 12 logged states.

mod inputs;
mod plot;
pub(crate) mod pooled;

pub use plot::{plot_states, write_svg, PlotKind};

use crate::discretize::{auto_substeps, discrete_step, Envelope, SubstepError};
use crate::identify::dataset::{build, DatasetError, DatasetOptions};
use crate::ir::ModelIr;
use crate::logs::{median, on_ground, run_touches_ground, FlightLog, Segment, StalePolicy, YAW};
use crate::metrics::{Metrics, MetricsError};
use crate::model::Model;
use inputs::{logged, ModelInputs};
use pooled::{MeanBook, Stat};
use serde::Serialize;
use std::borrow::Cow;
use std::fmt;

/// Default horizon: the MPC's N = 30 samples.
pub const DEFAULT_HORIZON: usize = 30;

/// A predicted state whose magnitude exceeds this (or that is not finite) has diverged.
pub const DIVERGENCE_BOUND: f64 = 1e6;

/// The dynamic rows vx..yaw_rate, compared in the one-step derivative check.
pub const DYNAMIC_STATES: std::ops::Range<usize> = 6..12;

const NX: usize = 12;
const NU: usize = 4;

/// How to evaluate.
#[derive(Clone, Debug)]
pub struct EvaluateOptions {
    /// Samples per horizon free run (default [`DEFAULT_HORIZON`]).
    pub horizon: usize,
    /// RK4 substeps per sample; `None` chooses them per sample period with
    /// [`auto_substeps`] over the default [`Envelope`] (as the code generator does).
    pub substeps: Option<usize>,
    /// How the one-step derivative targets are computed (Savitzky-Golay window and order,
    /// low-pass, edge trimming).
    pub dataset: DatasetOptions,
    /// What stale rows are (docs/logs.md#stale-rows): by default missing samples, interpolated —
    /// the same in `identify` and `diagnose`, so their figures are reproduced here.
    pub stale: StalePolicy,
}

impl Default for EvaluateOptions {
    fn default() -> Self {
        Self {
            horizon: DEFAULT_HORIZON,
            substeps: None,
            dataset: DatasetOptions::default(),
            stale: StalePolicy::default(),
        }
    }
}

/// Why an evaluation could not be made.
#[derive(Debug, thiserror::Error)]
pub enum EvaluateError {
    #[error("model `{model}` has {nx} states (besides the extra states of its corrections) and {nu} inputs, but flight logs have 12 states and 4 inputs")]
    Dimensions { model: String, nx: usize, nu: usize },
    #[error("no logs to evaluate")]
    NoLogs,
    #[error("the horizon must be at least 1 sample")]
    ZeroHorizon,
    #[error("the number of RK4 substeps must be at least 1")]
    ZeroSubsteps,
    #[error("derivative targets: {0}")]
    Dataset(#[from] DatasetError),
    #[error("{file}: segment {segment}: choosing RK4 substeps for Δt = {dt} s: {error}")]
    Substeps {
        file: String,
        segment: usize,
        dt: f64,
        error: SubstepError,
    },
    #[error("metrics: {0}")]
    Metrics(#[from] MetricsError),
    #[error("{files}: no segment has two samples: a one-step prediction needs a sample and the next one")]
    TooShort { files: String },
    #[error("{files}: the horizon of {horizon} samples is not shorter than any segment (the longest has {longest} samples): no horizon run can be scored; pass a smaller --horizon")]
    HorizonTooLong {
        files: String,
        horizon: usize,
        longest: usize,
    },
    #[error("{files}: every horizon run of {horizon} samples touches the ground (z ≤ 0.02 m, {runs} runs left out): there is no flight to score")]
    AllOnGround { files: String, horizon: usize, runs: usize },
    #[error("{path}: cannot write the plot: {message}")]
    Plot { path: String, message: String },
}

/// A one-step comparison (derivative or next sample).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OneStep {
    /// Predictions made.
    pub predictions: usize,
    /// Predictions left out because they were not finite or exceeded [`DIVERGENCE_BOUND`].
    pub excluded: usize,
    /// Over the remaining predictions; `None` if there are none.
    pub metrics: Option<Metrics>,
}

/// Free runs over the horizon, pooled.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Horizon {
    /// Samples per run.
    pub horizon: usize,
    /// Runs scored (one per sample that has `horizon` samples after it in its segment, unless a
    /// sample of the run is on the ground: `on_ground`).
    pub runs: usize,
    /// Runs that diverged before their end.
    pub diverged: usize,
    /// Runs left out because a sample of theirs is on the ground (z ≤ `logs::GROUND_CLEARANCE`),
    /// as `diagnose` leaves them out.
    pub on_ground: usize,
    /// All finite predictions of all runs (steps 1..=horizon) pooled.
    pub metrics: Option<Metrics>,
    /// The predictions at step `horizon` of the runs that reached it.
    pub end: Option<Metrics>,
    /// Overall RMSE (all states pooled) at each step 1..=horizon, over the runs that reached
    /// that step; `null` where none did.
    pub rmse_by_step: Vec<Option<f64>>,
    /// The predict-no-change baseline over the same runs and steps: every step of a run
    /// predicted as the run's first (logged) state. A model is worth flying only if its
    /// `metrics` beat this.
    pub no_change: Option<Metrics>,
}

/// Free runs over whole segments, pooled.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WholeFlight {
    /// Runs (segments with at least two samples).
    pub runs: usize,
    /// Runs that diverged.
    pub diverged: usize,
    /// All finite predictions (samples 1.. of each segment) pooled.
    pub metrics: Option<Metrics>,
}

/// One segment's figures.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentEvaluation {
    /// Index in the log's segments.
    pub segment: usize,
    pub samples: usize,
    pub t_start: f64,
    pub t_end: f64,
    /// The step used: the segment's median Δt (s).
    pub dt: f64,
    /// RK4 substeps per sample.
    pub substeps: usize,
    /// Whole-flight free run: the first sample (0-based, in the segment) whose prediction
    /// diverged, and its time.
    pub diverged_at: Option<usize>,
    pub diverged_t: Option<f64>,
    /// Whole-flight free run over this segment (finite part).
    pub whole_flight: Option<Metrics>,
    /// Horizon runs started in this segment and how many diverged; the start sample of the
    /// first that diverged.
    pub horizon_runs: usize,
    pub horizon_diverged: usize,
    pub first_diverged_horizon: Option<usize>,
}

/// One log's figures: the three kinds over its segments, and per segment.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LogEvaluation {
    pub source: String,
    pub one_step_derivative: OneStep,
    pub one_step_next: OneStep,
    pub horizon: Horizon,
    pub whole_flight: WholeFlight,
    pub segments: Vec<SegmentEvaluation>,
}

/// The evaluation of a model on a set of logs. Top-level figures pool all logs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Evaluation {
    pub model: String,
    pub model_kind: String,
    /// Whether the substeps were chosen automatically.
    pub substeps_auto: bool,
    pub divergence_bound: f64,
    /// Savitzky-Golay window and order of the derivative targets.
    pub savgol_window: usize,
    pub savgol_order: usize,
    /// The stale-row policy the figures were computed under (`interpolate` or `keep`).
    pub stale_policy: String,
    pub one_step_derivative: OneStep,
    pub one_step_next: OneStep,
    pub horizon: Horizon,
    pub whole_flight: WholeFlight,
    pub logs: Vec<LogEvaluation>,
}

/// Wrap an angle difference to (−π, π].
pub fn wrap_angle(d: f64) -> f64 {
    d.sin().atan2(d.cos())
}

fn finite(x: &[f64]) -> bool {
    x.iter().all(|v| v.is_finite() && v.abs() <= DIVERGENCE_BOUND)
}

/// Sum of squared errors (all states) and count of runs at each horizon step.
#[derive(Clone, Default)]
struct StepErrors {
    sq: Vec<f64>,
    runs: Vec<usize>,
}

impl StepErrors {
    fn new(h: usize) -> Self {
        Self {
            sq: vec![0.0; h],
            runs: vec![0; h],
        }
    }

    fn add(&mut self, step: usize, predicted: &[f64], observed: &[f64]) {
        let e: f64 = (0..NX)
            .map(|i| {
                let d = predicted[i] - observed[i];
                let d = if i == YAW { wrap_angle(d) } else { d };
                d * d
            })
            .sum();
        self.sq[step] += e;
        self.runs[step] += 1;
    }

    fn merge(&mut self, other: &StepErrors) {
        for j in 0..self.sq.len() {
            self.sq[j] += other.sq[j];
            self.runs[j] += other.runs[j];
        }
    }

    fn rmse(&self) -> Vec<Option<f64>> {
        self.sq
            .iter()
            .zip(&self.runs)
            .map(|(&s, &n)| (n > 0).then(|| (s / (n * NX) as f64).sqrt()))
            .collect()
    }
}

/// Everything accumulated for one log (or all logs): streamed pools ([`Stat`]) and counts.
struct Acc {
    derivative: Stat,
    derivative_made: usize,
    next: Stat,
    next_made: usize,
    horizon: Stat,
    horizon_end: Stat,
    horizon_no_change: Stat,
    steps: StepErrors,
    horizon_runs: usize,
    horizon_diverged: usize,
    horizon_on_ground: usize,
    whole: Stat,
    whole_runs: usize,
    whole_diverged: usize,
}

impl Acc {
    fn new(h: usize, book: &mut MeanBook) -> Self {
        Self {
            derivative: book.stat(DYNAMIC_STATES.len()),
            derivative_made: 0,
            next: book.stat(NX),
            next_made: 0,
            horizon: book.stat(NX),
            horizon_end: book.stat(NX),
            horizon_no_change: book.stat(NX),
            steps: StepErrors::new(h),
            horizon_runs: 0,
            horizon_diverged: 0,
            horizon_on_ground: 0,
            whole: book.stat(NX),
            whole_runs: 0,
            whole_diverged: 0,
        }
    }

    /// Add another accumulator's counts and step errors (its pools were pushed to this one's as
    /// they were to it, row by row, so that the sums are in pooled sample order).
    fn add_counts(&mut self, o: &Acc) {
        self.derivative_made += o.derivative_made;
        self.next_made += o.next_made;
        self.steps.merge(&o.steps);
        self.horizon_runs += o.horizon_runs;
        self.horizon_diverged += o.horizon_diverged;
        self.horizon_on_ground += o.horizon_on_ground;
        self.whole_runs += o.whole_runs;
        self.whole_diverged += o.whole_diverged;
    }

    #[allow(clippy::type_complexity)]
    fn finish(
        &self,
        h: usize,
        names: &[String],
        book: &mut MeanBook,
    ) -> Result<(OneStep, OneStep, Horizon, WholeFlight), MetricsError> {
        let dyn_names = &names[DYNAMIC_STATES];
        let derivative = OneStep {
            predictions: self.derivative_made,
            excluded: self.derivative_made - self.derivative.len(),
            metrics: self.derivative.metrics(dyn_names, book)?,
        };
        let next = OneStep {
            predictions: self.next_made,
            excluded: self.next_made - self.next.len(),
            metrics: self.next.metrics(names, book)?,
        };
        let horizon = Horizon {
            horizon: h,
            runs: self.horizon_runs,
            diverged: self.horizon_diverged,
            on_ground: self.horizon_on_ground,
            metrics: self.horizon.metrics(names, book)?,
            end: self.horizon_end.metrics(names, book)?,
            rmse_by_step: self.steps.rmse(),
            no_change: self.horizon_no_change.metrics(names, book)?,
        };
        let whole = WholeFlight {
            runs: self.whole_runs,
            diverged: self.whole_diverged,
            metrics: self.whole.metrics(names, book)?,
        };
        Ok((derivative, next, horizon, whole))
    }
}

/// Push a row into a log's pool and into the pool of all logs.
fn push2(a: &mut Stat, b: &mut Stat, predicted: &[f64], observed: &[f64], yaw: Option<usize>) {
    a.push(predicted, observed, yaw);
    b.push(predicted, observed, yaw);
}

/// Which pass of [`evaluate`]: `Means` runs no model and takes every prediction as the
/// observation (the pooled observations, hence the provisional means of the d₁ denominators,
/// are then those of the real pass unless a prediction diverges); `Model` runs the model.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pass {
    Means,
    Model,
}

/// The log as the stale-row policy sees it: borrowed when the policy changes nothing (no copy
/// of a big log).
fn stale_view(log: &FlightLog, policy: StalePolicy) -> Cow<'_, FlightLog> {
    let changes = policy == StalePolicy::Interpolate && log.segments.iter().any(|s| s.stale_flags().iter().any(|f| *f));
    if changes {
        Cow::Owned(log.with_stale(policy))
    } else {
        Cow::Borrowed(log)
    }
}

/// The model lowered once, with the step function.
struct Stepper {
    ir: ModelIr,
    fixed: Option<usize>,
    cache: Vec<(f64, usize)>,
}

impl Stepper {
    fn new(model: &Model, options: &EvaluateOptions) -> Result<Self, EvaluateError> {
        if model.base_nx() != NX || model.nu() != NU {
            return Err(EvaluateError::Dimensions {
                model: model.name.clone(),
                nx: model.base_nx(),
                nu: model.nu(),
            });
        }
        if options.horizon == 0 {
            return Err(EvaluateError::ZeroHorizon);
        }
        if options.substeps == Some(0) {
            return Err(EvaluateError::ZeroSubsteps);
        }
        Ok(Self {
            ir: ModelIr::new(model),
            fixed: options.substeps,
            cache: Vec::new(),
        })
    }

    fn substeps(&mut self, dt: f64, file: &str, segment: usize) -> Result<usize, EvaluateError> {
        if let Some(m) = self.fixed {
            return Ok(m);
        }
        if let Some(&(_, m)) = self.cache.iter().find(|(d, _)| *d == dt) {
            return Ok(m);
        }
        let m = auto_substeps(&self.ir, dt, &Envelope::default())
            .map_err(|error| EvaluateError::Substeps {
                file: file.to_string(),
                segment,
                dt,
                error,
            })?
            .substeps;
        self.cache.push((dt, m));
        Ok(m)
    }

    /// F(x, u) over the model's full state, or `None` if the result diverged.
    fn step(&self, x: &[f64], u: &[f64; NU], dt: f64, m: usize) -> Option<Vec<f64>> {
        let next = discrete_step(&self.ir, x, u, dt, m);
        finite(&next).then_some(next)
    }
}

/// The model's inputs for the one-step derivative check of a dataset segment, and the index of
/// the segment's first sample in them. Without a low-pass they are computed over the whole logged
/// segment (so delays and lag states see the samples the dataset trimmed); with one, over the
/// dataset's filtered series itself.
fn derivative_inputs(
    model: &Model,
    ir: &ModelIr,
    log: &FlightLog,
    seg: &crate::identify::dataset::SegmentData,
    options: &EvaluateOptions,
) -> (ModelInputs, usize) {
    let raw = log.segments.get(seg.segment);
    if options.dataset.lowpass.is_none() {
        if let Some(raw) = raw {
            let dt = segment_dt(raw).unwrap_or(seg.dt);
            if let Some(offset) = raw.t.iter().position(|&t| Some(&t) == seg.t.first()) {
                return (
                    ModelInputs::new(model, ir, &raw.t, &raw.x, &raw.u, raw.t[0], dt),
                    offset,
                );
            }
        }
    }
    let t_start = raw.map_or(seg.t[0], |r| r.t[0]);
    (ModelInputs::new(model, ir, &seg.t, &seg.x, &seg.u, t_start, seg.dt), 0)
}

/// The segment's median sample period, or `None` for a single sample.
fn segment_dt(seg: &Segment) -> Option<f64> {
    let steps: Vec<f64> = seg.t.windows(2).map(|w| w[1] - w[0]).collect();
    median(&steps).filter(|d| d.is_finite() && *d > 0.0)
}

/// The whole-flight free run of a segment: predictions for samples 0.. (sample 0 is the
/// measured initial state) up to, not including, the first diverged sample.
fn free_run(st: &Stepper, seg: &Segment, inputs: &ModelInputs, dt: f64, m: usize) -> (Vec<[f64; NX]>, Option<usize>) {
    let mut out = vec![seg.x[0]];
    let mut x = inputs.state(&seg.x[0], 0);
    for k in 0..seg.len() - 1 {
        match st.step(&x, &inputs.u[k], dt, m) {
            Some(next) => {
                out.push(logged(&next));
                x = next;
            }
            None => return (out, Some(k + 1)),
        }
    }
    (out, None)
}

/// A horizon run from sample k: predictions for k+1..=k+len (fewer if it diverged).
fn horizon_run(
    st: &Stepper,
    seg: &Segment,
    inputs: &ModelInputs,
    k: usize,
    len: usize,
    dt: f64,
    m: usize,
) -> Vec<[f64; NX]> {
    let mut out = Vec::with_capacity(len);
    let mut x = inputs.state(&seg.x[k], k);
    for j in 0..len {
        match st.step(&x, &inputs.u[k + j], dt, m) {
            Some(next) => {
                out.push(logged(&next));
                x = next;
            }
            None => break,
        }
    }
    out
}

/// Evaluate `model` on `logs`: one-step (derivative and next sample), horizon free runs and
/// whole-flight free runs, per segment, per log and pooled over all logs.
///
/// The predictions are streamed into their metrics, never stored (memory: the logs, one log's
/// derivative targets and a few series per segment; docs/evaluate.md). The d₁ of a pool needs
/// its observations' mean, so the metrics are made in one pass with means computed beforehand
/// from the logs alone, and in a second pass over the same predictions where a diverged or
/// excluded prediction changed a pool's mean (see `pooled.rs`); the figures are those of
/// [`compare`](crate::metrics::compare) on the pooled rows, to the bit.
pub fn evaluate(model: &Model, logs: &[FlightLog], options: &EvaluateOptions) -> Result<Evaluation, EvaluateError> {
    let mut means = MeanBook::default();
    // Failures of the means pass are found again, in their order, by the model pass.
    let _ = evaluate_pass(model, logs, options, Pass::Means, &mut means);
    let mut book = MeanBook::with_means(means.found());
    let evaluation = evaluate_pass(model, logs, options, Pass::Model, &mut book)?;
    if book.exact() {
        return Ok(evaluation);
    }
    let mut exact = MeanBook::with_means(book.found());
    evaluate_pass(model, logs, options, Pass::Model, &mut exact)
}

fn evaluate_pass(
    model: &Model,
    logs: &[FlightLog],
    options: &EvaluateOptions,
    pass: Pass,
    book: &mut MeanBook,
) -> Result<Evaluation, EvaluateError> {
    if logs.is_empty() {
        return Err(EvaluateError::NoLogs);
    }
    let mut st = Stepper::new(model, options)?;
    let names = model.base_states().to_vec();
    let h = options.horizon;
    let model_pass = pass == Pass::Model;

    let mut total = Acc::new(h, book);
    let mut per_log = Vec::with_capacity(logs.len());
    for log in logs {
        let log = stale_view(log, options.stale);
        let log = log.as_ref();
        let mut acc = Acc::new(h, book);
        // 1a. One-step derivative on the dataset's (possibly filtered, trimmed) samples, built
        //     for this log alone and dropped after use.
        let dataset = match build(std::slice::from_ref(log), &options.dataset) {
            Ok(d) => Some(d),
            Err(DatasetError::Empty { .. }) => None,
            Err(e) => return Err(e.into()),
        };
        for seg in dataset.iter().flat_map(|d| &d.segments) {
            if !model_pass {
                for dx in &seg.dx {
                    acc.derivative_made += 1;
                    let d = &dx[DYNAMIC_STATES];
                    push2(&mut acc.derivative, &mut total.derivative, d, d, None);
                }
                continue;
            }
            let (inputs, offset) = derivative_inputs(model, &st.ir, log, seg, options);
            for (j, (x, dx)) in seg.x.iter().zip(&seg.dx).enumerate() {
                acc.derivative_made += 1;
                let f = st.ir.eval_f(&inputs.state(x, offset + j), &inputs.u[offset + j]);
                if finite(&f) {
                    push2(
                        &mut acc.derivative,
                        &mut total.derivative,
                        &f[DYNAMIC_STATES],
                        &dx[DYNAMIC_STATES],
                        None,
                    );
                }
            }
        }
        drop(dataset);
        let mut segments = Vec::new();
        for (si, seg) in log.segments.iter().enumerate() {
            let n = seg.len();
            let Some(dt) = segment_dt(seg) else {
                continue;
            };
            let (m, inputs) = if model_pass {
                let m = st.substeps(dt, &log.source, si)?;
                (
                    m,
                    Some(ModelInputs::new(model, &st.ir, &seg.t, &seg.x, &seg.u, seg.t[0], dt)),
                )
            } else {
                (1, None)
            };
            // 1b. One-step next sample.
            for k in 0..n - 1 {
                acc.next_made += 1;
                let p = match &inputs {
                    Some(inputs) => st.step(&inputs.state(&seg.x[k], k), &inputs.u[k], dt, m),
                    None => Some(seg.x[k + 1].to_vec()),
                };
                if let Some(p) = p {
                    push2(&mut acc.next, &mut total.next, &p[..NX], &seg.x[k + 1], Some(YAW));
                }
            }
            // 2. Horizon free runs from every sample with a full horizon after it, clear of the
            //    ground (diagnose's rule).
            let ground = on_ground(&seg.x);
            let (mut runs, mut diverged, mut first_diverged) = (0, 0, None);
            for k in 0..n.saturating_sub(h) {
                if run_touches_ground(&ground, k, h) {
                    acc.horizon_on_ground += 1;
                    continue;
                }
                runs += 1;
                for j in 1..=h {
                    push2(
                        &mut acc.horizon_no_change,
                        &mut total.horizon_no_change,
                        &seg.x[k],
                        &seg.x[k + j],
                        Some(YAW),
                    );
                }
                let pred = match &inputs {
                    Some(inputs) => horizon_run(&st, seg, inputs, k, h, dt, m),
                    None => seg.x[k + 1..=k + h].to_vec(),
                };
                for (j, p) in pred.iter().enumerate() {
                    push2(&mut acc.horizon, &mut total.horizon, p, &seg.x[k + j + 1], Some(YAW));
                    acc.steps.add(j, p, &seg.x[k + j + 1]);
                }
                if pred.len() == h {
                    push2(
                        &mut acc.horizon_end,
                        &mut total.horizon_end,
                        &pred[h - 1],
                        &seg.x[k + h],
                        Some(YAW),
                    );
                } else {
                    diverged += 1;
                    first_diverged.get_or_insert(k);
                }
            }
            drop(ground);
            acc.horizon_runs += runs;
            acc.horizon_diverged += diverged;
            // 3. Whole-flight free run, streamed.
            let mut pool = book.stat(NX);
            let mut diverged_at = None;
            match &inputs {
                Some(inputs) => {
                    let mut x = inputs.state(&seg.x[0], 0);
                    for k in 0..n - 1 {
                        let Some(next) = st.step(&x, &inputs.u[k], dt, m) else {
                            diverged_at = Some(k + 1);
                            break;
                        };
                        let p = logged(&next);
                        pool.push(&p, &seg.x[k + 1], Some(YAW));
                        push2(&mut acc.whole, &mut total.whole, &p, &seg.x[k + 1], Some(YAW));
                        x = next;
                    }
                }
                None => {
                    for o in &seg.x[1..] {
                        pool.push(o, o, Some(YAW));
                        push2(&mut acc.whole, &mut total.whole, o, o, Some(YAW));
                    }
                }
            }
            acc.whole_runs += 1;
            acc.whole_diverged += diverged_at.is_some() as usize;
            segments.push(SegmentEvaluation {
                segment: si,
                samples: n,
                t_start: seg.t[0],
                t_end: seg.t[n - 1],
                dt,
                substeps: m,
                diverged_at,
                diverged_t: diverged_at.map(|k| seg.t[k]),
                whole_flight: pool.metrics(&names, book)?,
                horizon_runs: runs,
                horizon_diverged: diverged,
                first_diverged_horizon: first_diverged,
            });
        }
        let (one_step_derivative, one_step_next, horizon, whole_flight) = acc.finish(h, &names, book)?;
        total.add_counts(&acc);
        per_log.push(LogEvaluation {
            source: log.source.clone(),
            one_step_derivative,
            one_step_next,
            horizon,
            whole_flight,
            segments,
        });
    }
    // Degenerate data is an error, not an evaluation with nothing in it.
    let files = || logs.iter().map(|l| l.source.as_str()).collect::<Vec<_>>().join(", ");
    if total.next_made == 0 {
        return Err(EvaluateError::TooShort { files: files() });
    }
    if total.horizon_runs == 0 && total.horizon_on_ground > 0 {
        return Err(EvaluateError::AllOnGround {
            files: files(),
            horizon: h,
            runs: total.horizon_on_ground,
        });
    }
    if total.horizon_runs == 0 {
        let longest = logs
            .iter()
            .flat_map(|l| &l.segments)
            .map(|s| s.len())
            .max()
            .unwrap_or(0);
        return Err(EvaluateError::HorizonTooLong {
            files: files(),
            horizon: h,
            longest,
        });
    }
    let (one_step_derivative, one_step_next, horizon, whole_flight) = total.finish(h, &names, book)?;
    Ok(Evaluation {
        model: model.name.clone(),
        model_kind: model.kind_name().to_string(),
        substeps_auto: options.substeps.is_none(),
        divergence_bound: DIVERGENCE_BOUND,
        savgol_window: options.dataset.savgol.window,
        savgol_order: options.dataset.savgol.order,
        stale_policy: options.stale.name().to_string(),
        one_step_derivative,
        one_step_next,
        horizon,
        whole_flight,
        logs: per_log,
    })
}

/// What [`horizon_score`] gives: the pooled horizon free runs.
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonScore {
    pub runs: usize,
    pub diverged: usize,
    /// Overall RMSE of every finite prediction of every run (all states pooled).
    pub overall_rmse: Option<f64>,
}

/// The horizon free runs of [`evaluate`] alone, from every `stride`-th sample of each segment
/// (the first included): with `stride` 1 the runs, divergences and overall RMSE of
/// `evaluate(model, logs, options)?.horizon`, the same numbers, without the one-step and
/// whole-flight figures (the delay refinement of `identify` scores candidates by this alone, and
/// free runs that start a few milliseconds apart are nearly the same run). It fails where
/// `evaluate` does for the horizon's reasons (no logs, a model of other dimensions, no run to
/// score); on logs whose other figures `evaluate` cannot compute it still answers.
pub fn horizon_score(
    model: &Model,
    logs: &[FlightLog],
    options: &EvaluateOptions,
    stride: usize,
) -> Result<HorizonScore, EvaluateError> {
    if logs.is_empty() {
        return Err(EvaluateError::NoLogs);
    }
    let mut st = Stepper::new(model, options)?;
    let names = model.base_states().to_vec();
    let h = options.horizon;
    let stride = stride.max(1);
    let mut pool = MeanBook::default().stat(NX);
    let (mut runs, mut diverged, mut on_ground_runs, mut next_made) = (0usize, 0usize, 0usize, 0usize);
    for log in logs {
        let log = stale_view(log, options.stale);
        let log = log.as_ref();
        for (si, seg) in log.segments.iter().enumerate() {
            let n = seg.len();
            let Some(dt) = segment_dt(seg) else {
                continue;
            };
            let m = st.substeps(dt, &log.source, si)?;
            next_made += n - 1;
            let inputs = ModelInputs::new(model, &st.ir, &seg.t, &seg.x, &seg.u, seg.t[0], dt);
            let ground = on_ground(&seg.x);
            for k in (0..n.saturating_sub(h)).step_by(stride) {
                if run_touches_ground(&ground, k, h) {
                    on_ground_runs += 1;
                    continue;
                }
                runs += 1;
                let pred = horizon_run(&st, seg, &inputs, k, h, dt, m);
                for (j, p) in pred.iter().enumerate() {
                    pool.push(p, &seg.x[k + j + 1], Some(YAW));
                }
                if pred.len() < h {
                    diverged += 1;
                }
            }
        }
    }
    let files = || logs.iter().map(|l| l.source.as_str()).collect::<Vec<_>>().join(", ");
    if next_made == 0 {
        return Err(EvaluateError::TooShort { files: files() });
    }
    if runs == 0 && on_ground_runs > 0 {
        return Err(EvaluateError::AllOnGround {
            files: files(),
            horizon: h,
            runs: on_ground_runs,
        });
    }
    if runs == 0 {
        let longest = logs
            .iter()
            .flat_map(|l| &l.segments)
            .map(|s| s.len())
            .max()
            .unwrap_or(0);
        return Err(EvaluateError::HorizonTooLong {
            files: files(),
            horizon: h,
            longest,
        });
    }
    Ok(HorizonScore {
        runs,
        diverged,
        overall_rmse: pool.overall_rmse(&names)?,
    })
}

/// Measured and predicted trajectories of one segment, for plots.
#[derive(Clone, Debug)]
pub struct SegmentTraces {
    pub segment: usize,
    pub t: Vec<f64>,
    pub measured: Vec<[f64; NX]>,
    /// Whole-flight free run from sample 0, up to the divergence if any.
    pub free_run: Vec<[f64; NX]>,
    pub diverged_at: Option<usize>,
    /// Horizon free runs restarted every `horizon` samples (non-overlapping): (start sample,
    /// predictions for start, start+1, …; the first is the measured start state).
    pub horizon_runs: Vec<(usize, Vec<[f64; NX]>)>,
    pub horizon: usize,
}

/// The traces of every segment (with at least two samples) of `log`.
pub fn traces(model: &Model, log: &FlightLog, options: &EvaluateOptions) -> Result<Vec<SegmentTraces>, EvaluateError> {
    let mut st = Stepper::new(model, options)?;
    let h = options.horizon;
    let mut out = Vec::new();
    for (si, seg) in log.segments.iter().enumerate() {
        let Some(dt) = segment_dt(seg) else {
            continue;
        };
        let m = st.substeps(dt, &log.source, si)?;
        let inputs = ModelInputs::new(model, &st.ir, &seg.t, &seg.x, &seg.u, seg.t[0], dt);
        let (free_run, diverged_at) = free_run(&st, seg, &inputs, dt, m);
        let horizon_runs = (0..seg.len() - 1)
            .step_by(h)
            .map(|k| {
                let len = h.min(seg.len() - 1 - k);
                let mut run = vec![seg.x[k]];
                run.extend(horizon_run(&st, seg, &inputs, k, len, dt, m));
                (k, run)
            })
            .collect();
        out.push(SegmentTraces {
            segment: si,
            t: seg.t.clone(),
            measured: seg.x.clone(),
            free_run,
            diverged_at,
            horizon_runs,
            horizon: h,
        });
    }
    Ok(out)
}

fn overall(m: &Option<Metrics>) -> String {
    match m {
        Some(m) => format!(
            "RMSE {:.4}  MAE {:.4}  d1 {:.4}  ({} samples)",
            m.overall_rmse, m.overall_mae, m.overall_d1, m.samples
        ),
        None => "no finite predictions".to_string(),
    }
}

impl fmt::Display for Evaluation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "model {} ({}), {} log(s), stale rows: {}",
            self.model,
            self.model_kind,
            self.logs.len(),
            self.stale_policy
        )?;
        let d = &self.one_step_derivative;
        writeln!(f, "one-step derivative (vx..yaw_rate): {}", overall(&d.metrics))?;
        let n = &self.one_step_next;
        writeln!(f, "one-step next sample:               {}", overall(&n.metrics))?;
        let h = &self.horizon;
        writeln!(
            f,
            "free run over {} samples:           {}; {} of {} runs diverged",
            h.horizon,
            overall(&h.metrics),
            h.diverged,
            h.runs
        )?;
        writeln!(f, "  at the end of the horizon:        {}", overall(&h.end))?;
        writeln!(f, "  predict-no-change, same runs:     {}", overall(&h.no_change))?;
        let w = &self.whole_flight;
        writeln!(
            f,
            "free run over the whole flight:     {}; {} of {} runs diverged",
            overall(&w.metrics),
            w.diverged,
            w.runs
        )?;
        for log in &self.logs {
            for s in &log.segments {
                if let (Some(k), Some(t)) = (s.diverged_at, s.diverged_t) {
                    writeln!(
                        f,
                        "  {} segment {}: the whole-flight free run diverged at sample {} (t = {} s)",
                        log.source, s.segment, k, t
                    )?;
                }
            }
        }
        Ok(())
    }
}
