//! `uavgen diagnose`: where a model parts from flight data, which catalogued effect explains the
//! gap, how far adding it shrinks the gap on held-out data, and the corrected model. See
//! docs/diagnose.md.
//!
//! 1. **Where** ([`where_link`]): the base model's residuals (one-step and over the horizon) on the
//!    training logs, analysed by [`crate::analysis`].
//! 2. **Which effect** ([`catalogue`], [`candidate`], [`select`]): every catalogued effect is
//!    fitted on the training logs as an augmentation of the base model and scored on held-out data
//!    (`--holdout` logs, else cross-validation); significant effects are named greedily.
//! 3. **How far it shrinks** ([`shrink`]): one-step and horizon RMSE and d₁ per state, before and
//!    after, on held-out data.
//! 4. **The corrected model** ([`corrected`]): the model file with a `corrections` block.
//!
//! ```no_run
//! use uavgen::diagnose::{diagnose, DiagnoseOptions};
//! let model = uavgen::load("base.json".as_ref()).unwrap();
//! let train = vec![uavgen::logs::read_log("drag_train.csv".as_ref()).unwrap()];
//! let test = vec![uavgen::logs::read_log("drag_test.csv".as_ref()).unwrap()];
//! let d = diagnose(&model, &train, &test, &DiagnoseOptions::default()).unwrap();
//! println!("verdict: {:?}", d.verdict);
//! d.write("diagnosis".as_ref(), false).unwrap();
//! ```

mod assemble;
mod augmented;
mod candidate;
pub mod catalogue;
mod corrected;
mod data;
mod design;
mod envelope;
mod fcache;
pub mod fit;
mod horizon_fit;
mod horizon_rule;
mod inherited;
mod input_fit;
mod loop_fit;
pub mod physical;
mod plots;
mod problem;
mod report_json;
mod report_md;
mod residuals;
mod response_fit;
pub mod response_time;
pub mod score;
mod scored;
mod select;
mod shrink;
mod where_link;
mod write;

pub use catalogue::EffectKind;
pub use report_json::{EffectReport, InputScan, RoundEntry, RoundReport};
pub use residuals::ResidualKind;
pub use score::Rules;
pub use shrink::{ClosedLoop, ClosedLoopRun, Shrink, Side, StateShrink};

use crate::analysis::WhereReport;
use crate::identify::preprocess::SavGol;
use crate::logs::{FlightLog, INPUT_COLUMNS};
use crate::model::{Corrections, Model};
use augmented::Augmented;
use catalogue::linear::Context;
use serde::Serialize;
use std::path::PathBuf;

/// Settings of the diagnosis. `Default` gives the documented values.
#[derive(Clone, Debug, Serialize)]
pub struct DiagnoseOptions {
    /// Savitzky-Golay differentiation of the logs (window 9, order 3).
    pub savgol: SavGol,
    /// How model and data are compared (default: the matched filter; docs/diagnose.md).
    pub residual: ResidualKind,
    /// Free-run horizon in samples (30, the MPC's).
    pub horizon: usize,
    /// RK4 substeps per sample; `None`: the code generator's automatic rule.
    pub substeps: Option<usize>,
    /// g of the thrust corrections; `None`: the PD model's gravity, else 9.81 m/s².
    pub gravity: Option<f64>,
    /// Rotor radius R of the ground effect, m (0.1651, the Matrice 100's).
    pub rotor_radius: f64,
    /// Largest delay scanned, in samples (10); `latency`'s scan reaches at least 1/3 s whatever the
    /// rate (coarser whole-sample steps on fast logs, then every sample and quarter samples around
    /// the best; docs/diagnose.md#fitting).
    pub max_delay_samples: f64,
    /// Time constants scanned for the actuator lag, s (24 values from 0.01 to 1 s, logarithmic).
    pub lag_grid: Vec<f64>,
    /// Cross-validation parts of a lone training segment when there is no held-out log (4).
    pub folds: usize,
    /// When an effect is significant.
    pub rules: Rules,
    /// The candidates evaluated (default: the whole catalogue).
    pub candidates: Vec<EffectKind>,
    /// Run the "where" analysis (default true).
    pub where_analysis: bool,
    /// The text of the model file, for corrected.json; `None`: read from the model's source path.
    #[serde(skip)]
    pub model_text: Option<String>,
    /// The `source` of the corrections block (default `uavgen diagnose`).
    pub source: Option<String>,
    /// Stale rows (docs/logs.md#stale-rows): `Interpolate` (the default) treats them as missing
    /// from the start — every figure, before and after, is computed on the interpolated data, as
    /// `uavgen evaluate` and `uavgen identify` do by default, and `stale_samples` is reported as
    /// a data finding; `Keep` uses the logs as recorded (and leaves `stale_samples` out).
    pub stale: crate::logs::StalePolicy,
    /// A plant file for the closed-loop comparison (pending: recorded, not used yet).
    pub plant: Option<PathBuf>,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        Self {
            savgol: SavGol { window: 9, order: 3 },
            residual: ResidualKind::Matched,
            horizon: 30,
            substeps: None,
            gravity: None,
            rotor_radius: 0.1651,
            max_delay_samples: 10.0,
            lag_grid: catalogue::inputs::lag_grid(0.01, 1.0, 24),
            folds: 4,
            rules: Rules::default(),
            candidates: EffectKind::ALL.to_vec(),
            where_analysis: true,
            model_text: None,
            source: None,
            plant: None,
            stale: crate::logs::StalePolicy::Interpolate,
        }
    }
}

/// Why a diagnosis could not be made or written.
#[derive(Debug, thiserror::Error)]
pub enum DiagnoseError {
    #[error("model `{model}` has {nx} states and {nu} inputs, but flight logs have 12 states and 4 inputs")]
    Dimensions { model: String, nx: usize, nu: usize },
    #[error("model `{model}` has a `corrections` block with more than an input response (latency, actuator_lag); diagnose its base model (the file without those corrections)")]
    HasCorrections { model: String },
    #[error("no training logs")]
    NoLogs,
    #[error("{what}: no segment has at least {rows} rows (the Savitzky-Golay window + 2)")]
    NoData { what: String, rows: usize },
    #[error("{file}: {message}")]
    Data { file: String, message: String },
    #[error("{file}: choosing RK4 substeps for Δt = {dt} s: {message}")]
    Substeps { file: String, dt: f64, message: String },
    #[error("invalid option: {0}")]
    Options(String),
    #[error("the corrected model: {0}")]
    Corrected(String),
    #[error("{path}: {message}")]
    Write { path: String, message: String },
}

/// A log in the report.
#[derive(Clone, Debug, Serialize)]
pub struct LogSummary {
    pub source: String,
    pub rows: usize,
    pub segments: usize,
    /// Rows repeating the previous row's states.
    pub stale_rows: usize,
    /// Samples with residuals (segment interiors; parts shorter than the window are skipped).
    pub samples: usize,
}

/// Which held-out data scored the candidates.
#[derive(Clone, Debug, Serialize)]
pub struct Holdout {
    /// `"logs"` (the `--holdout` logs) or `"cross-validation"`.
    pub mode: String,
    pub logs: Vec<LogSummary>,
    /// Cross-validation folds (1 with held-out logs).
    pub folds: usize,
    /// How the folds were formed.
    pub description: String,
    /// Fraction of the held-out samples inside the training envelope, which alone score the
    /// candidates (1 in cross-validation; docs/diagnose.md).
    pub scored_fraction: f64,
}

/// The model in the report.
#[derive(Clone, Debug, Serialize)]
pub struct ModelSummary {
    pub name: String,
    pub kind: String,
    pub file: String,
    pub sha256: String,
    pub gravity: f64,
}

/// The result of [`diagnose`].
#[derive(Clone, Debug, Serialize)]
pub struct Diagnosis {
    pub model: ModelSummary,
    pub logs: Vec<LogSummary>,
    pub holdout: Holdout,
    /// Every candidate evaluated: the named ones first (in the order named, with the figures of
    /// the round that named them), then the others by score (figures of the last round).
    pub effects: Vec<EffectReport>,
    /// The named effects in order, or `["none"]`.
    pub verdict: Vec<String>,
    pub shrink: Shrink,
    /// The gap before and after on noise-free copies of the held-out logs
    /// ([`diagnose_with_reference`]; absent otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<ReferenceShrink>,
    #[serde(rename = "where")]
    pub where_report: Option<WhereReport>,
    /// The greedy selection round by round.
    pub rounds: Vec<RoundReport>,
    /// The block written into corrected.json.
    pub corrections: Corrections,
    /// corrected.json: the model file with the corrections block (null if the model text was not
    /// available; see [`Diagnosis::corrected_from`]).
    #[serde(skip)]
    pub corrected: serde_json::Value,
    pub notes: Vec<String>,
    /// What keeps the diagnosis physical ([`physical`]; docs/diagnose.md#physical-checks): effects
    /// not named because they were implausible or cancelled a named one, named effects that
    /// cancel or left their range after backfitting, and command channels the corrections slow
    /// down more than 2× ("SUSPICIOUS, not recommended"). Printed on stderr by the CLI.
    pub warnings: Vec<String>,
    /// How each command channel answers, base model against corrected model (step responses,
    /// [`response_time`]).
    pub response_times: Vec<response_time::ChannelTime>,
    pub options: DiagnoseOptions,
}

/// The model gap on noise-free logs of the held-out flights: the base model and the model with
/// the named effects, one step and over the horizon (the figures of [`Shrink`]).
#[derive(Clone, Debug, Serialize)]
pub struct ReferenceShrink {
    pub data: String,
    pub before: Side,
    pub after: Side,
}

/// The model text with `corrections` attached, as a JSON value.
fn corrected_value(text: &str, label: &str, corrections: &Corrections) -> Result<serde_json::Value, DiagnoseError> {
    let corrected = crate::model::attach_corrections(text, label, corrections)
        .map_err(|e| DiagnoseError::Corrected(e.to_string()))?;
    serde_json::from_str(&corrected).map_err(|e| DiagnoseError::Corrected(e.to_string()))
}

impl Diagnosis {
    /// Set [`Diagnosis::corrected`] from the model file's text (when it was not available).
    pub fn corrected_from(&mut self, model_text: &str) -> Result<(), DiagnoseError> {
        self.corrected = corrected_value(model_text, &self.model.file, &self.corrections)?;
        Ok(())
    }
}

/// Progress of [`diagnose_with_progress`].
#[derive(Clone, Debug)]
pub struct Progress<'a> {
    /// Candidate evaluations done and the total known so far (it grows by round).
    pub done: usize,
    pub total: usize,
    /// What is being done.
    pub what: &'a str,
}

fn summaries(logs: &[FlightLog], data: &[data::SegData], holdout: bool) -> Vec<LogSummary> {
    logs.iter()
        .enumerate()
        .map(|(i, l)| LogSummary {
            source: l.source.clone(),
            rows: l.rows(),
            segments: l.segments.len(),
            stale_rows: l.report.stale_states(),
            samples: data
                .iter()
                .filter(|s| s.holdout == holdout && s.log == i)
                .map(|s| s.dx.len())
                .sum(),
        })
        .collect()
}

/// The base of the diagnosis: the model lowered without its `corrections` block, with the input
/// response the block gives ([`inherited`]).
fn base_of(model: &Model, options: &DiagnoseOptions) -> Result<residuals::Base, DiagnoseError> {
    let (stripped, own) = inherited::split(model)?;
    let mut base = residuals::Base::new(&stripped, options.substeps, options.gravity);
    base.own = own;
    Ok(base)
}

fn check(model: &Model, train: &[FlightLog], options: &DiagnoseOptions) -> Result<(), DiagnoseError> {
    let (model, _) = inherited::split(model)?;
    let model = &model;
    if model.nx() != 12 || model.nu() != 4 {
        return Err(DiagnoseError::Dimensions {
            model: model.name.clone(),
            nx: model.nx(),
            nu: model.nu(),
        });
    }
    if train.is_empty() {
        return Err(DiagnoseError::NoLogs);
    }
    options
        .savgol
        .validate()
        .map_err(|e| DiagnoseError::Options(format!("Savitzky-Golay: {e}")))?;
    let bad = |what: &str| Err(DiagnoseError::Options(what.to_string()));
    if options.horizon == 0 {
        return bad("the horizon must be at least 1 sample");
    }
    if options.substeps == Some(0) {
        return bad("the number of RK4 substeps must be at least 1");
    }
    if !(options.rotor_radius.is_finite() && options.rotor_radius > 0.0) {
        return bad("the rotor radius must be a positive number of metres");
    }
    if !(options.max_delay_samples.is_finite() && options.max_delay_samples >= 1.0) {
        return bad("the largest delay must be at least 1 sample");
    }
    if options.lag_grid.is_empty() || options.lag_grid.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
        return bad("the lag grid must hold positive time constants");
    }
    if options.folds < 2 {
        return bad("cross-validation needs at least 2 folds");
    }
    if options.gravity.is_some_and(|g| !(g.is_finite() && g > 0.0)) {
        return bad("gravity must be a positive number");
    }
    Ok(())
}

/// Diagnose `model` on the `train` logs, scoring on the `holdout` logs (cross-validation over the
/// training logs when empty).
pub fn diagnose(
    model: &Model,
    train: &[FlightLog],
    holdout: &[FlightLog],
    options: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    diagnose_with_progress(model, train, holdout, options, &mut |_| {})
}

/// [`diagnose`] reporting progress over the candidate evaluations.
pub fn diagnose_with_progress(
    model: &Model,
    train: &[FlightLog],
    holdout: &[FlightLog],
    options: &DiagnoseOptions,
    progress: &mut dyn FnMut(Progress),
) -> Result<Diagnosis, DiagnoseError> {
    run(model, train, holdout, &[], options, progress)
}

/// [`diagnose`], and the gap before and after the named effects measured once more on
/// `reference`: the held-out flights logged without sensor noise, row for row (simulation only,
/// [`crate::sim::SimulatedLog::noise_free`]). Selection and fits never see `reference`; it only
/// measures what the corrected model gains against the plant itself ([`Diagnosis::reference`]).
pub fn diagnose_with_reference(
    model: &Model,
    train: &[FlightLog],
    holdout: &[FlightLog],
    reference: &[FlightLog],
    options: &DiagnoseOptions,
) -> Result<Diagnosis, DiagnoseError> {
    if holdout.is_empty() || reference.len() != holdout.len() {
        return Err(DiagnoseError::Options(format!(
            "{} reference logs for {} held-out logs: give one noise-free copy per held-out log",
            reference.len(),
            holdout.len()
        )));
    }
    for (r, h) in reference.iter().zip(holdout) {
        let shape = |l: &FlightLog| l.segments.iter().map(|s| s.len()).collect::<Vec<_>>();
        if shape(r) != shape(h) {
            return Err(DiagnoseError::Data {
                file: r.source.clone(),
                message: format!("its segments do not match the held-out log {} row for row", h.source),
            });
        }
    }
    run(model, train, holdout, reference, options, &mut |_| {})
}

/// The base model's one-step and horizon figures on `logs` alone (no selection): in the
/// self-check, its error on the held-out flight flown without the effect, which the effect's
/// correction cannot be expected to remove.
pub fn base_side(model: &Model, logs: &[FlightLog], options: &DiagnoseOptions) -> Result<Side, DiagnoseError> {
    check(model, logs, options)?;
    let base = base_of(model, options)?;
    let ctx = Context {
        gravity: base.gravity,
        rotor_radius: options.rotor_radius,
    };
    let data = data::prepare(&base, &options.savgol, options.residual, &[], logs, 1)?;
    let plain = Augmented::plain(&base, ctx);
    Ok(shrink::side(|pool| {
        for seg in &data.raw {
            pool.add(&plain, seg, options.horizon);
        }
    }))
}

/// `[j][c]`: dynamic row c of the base model depends on input j (structurally, from the IR).
fn input_rows(base: &residuals::Base) -> [[bool; 6]; 4] {
    let mut out = [[false; 6]; 4];
    for j in 0..4 {
        for c in 0..6 {
            out[j][c] = !base.ir.graph.is_zero(base.ir.fu[6 + c][j]);
        }
    }
    out
}

/// Per channel, the smallest mean squared residual taken as real (see `Problem::floor`).
fn floor(data: &data::Prepared) -> [f64; 6] {
    let mut floor = [0.0; 6];
    let count: usize = data.raw.iter().map(|s| s.dx.len()).sum();
    for seg in &data.raw {
        for d in &seg.dx {
            for c in 0..6 {
                floor[c] += d[c] * d[c] / count.max(1) as f64;
            }
        }
    }
    floor.map(|ms| 1e-16 * ms)
}

/// The delays the cross-correlation finds (command → driven state, prewhitened, significant and
/// localised): grid points of channel_response's scan.
fn seeds(where_report: Option<&WhereReport>) -> [Option<f64>; 4] {
    let mut seeds = [None; 4];
    if let Some(w) = where_report {
        for (j, lag) in w.response_lags.iter().enumerate().take(4) {
            let x = &lag.xcorr;
            if x.significant && x.localised && x.peak_seconds > 0.0 {
                seeds[j] = Some(x.peak_seconds);
            }
        }
    }
    seeds
}

fn run(
    model: &Model,
    train: &[FlightLog],
    holdout: &[FlightLog],
    reference: &[FlightLog],
    options: &DiagnoseOptions,
    progress: &mut dyn FnMut(Progress),
) -> Result<Diagnosis, DiagnoseError> {
    check(model, train, options)?;
    let base = base_of(model, options)?;
    let ctx = Context {
        gravity: base.gravity,
        rotor_radius: options.rotor_radius,
    };
    // A lone training segment without held-out logs is cut into parts for cross-validation.
    let train_segments: usize = train.iter().map(|l| l.segments.len()).sum();
    let split = if holdout.is_empty() && train_segments < 2 {
        options.folds
    } else {
        1
    };
    let data = prepare_data(&base, options, train, holdout, split, progress)?;
    let (fits, cv) = problem::folds(&data);
    if cv && fits.len() < 3 {
        return Err(DiagnoseError::NoData {
            what: "cross-validation (no held-out logs): at least two parts".into(),
            rows: options.savgol.window + 2,
        });
    }
    // Held-out samples outside the training envelope are not scored (all are in cross-validation).
    let (mask, inside) = if cv {
        (data.raw.iter().map(|s| s.airborne.clone()).collect(), 1.0)
    } else {
        envelope::masks(&data.raw)
    };
    let where_report = where_analysis(&base, ctx, &data, train, options, progress);
    let problem = problem::Problem {
        base: &base,
        data: &data,
        fits,
        cv,
        ctx,
        options,
        input_rows: input_rows(&base),
        floor: floor(&data),
        mask,
        seeds: seeds(where_report.as_ref()),
        seen: Default::default(),
    };
    let (state, rounds) = select::select(
        &problem,
        &options.candidates,
        &options.rules,
        &mut |done, total, what| progress(Progress { done, total, what }),
    );

    let response_times = response_time::compare(&problem, &state);
    let warnings = physical_warnings(&problem, &state, &rounds, &response_times);
    // Parameters of the named effects: the final fit; per fold for the cross-validated shrink.
    let fin = problem.final_fit();
    let (linear, mut notes) = catalogue::linear::linear_parameters(&state.linear, &state.theta[fin]);
    let source = options
        .source
        .clone()
        .unwrap_or_else(|| format!("uavgen {} diagnose", env!("CARGO_PKG_VERSION")));
    let inputs: Vec<String> = INPUT_COLUMNS.iter().map(|s| s.to_string()).collect();
    let corrections = corrected::corrections(&state, &linear, &inputs, options.rotor_radius, source);
    let (shrink, reference) = shrink_figures(&problem, &state, reference, progress)?;

    let effects = assemble::effects(&rounds, &state, &linear, options.rotor_radius);
    let rounds_report = assemble::rounds(&rounds);
    notes.extend(inherited::note(&base.own, &model.inputs));
    notes.extend(assemble::notes(&data, &state, options));
    let response_named = [
        EffectKind::Latency,
        EffectKind::ActuatorLag,
        EffectKind::ChannelResponse,
        EffectKind::LoopMismatch,
    ];
    if state.named.iter().any(|k| response_named.contains(k)) {
        notes.extend(assemble::xcorr_note(where_report.as_ref(), &response_times));
    }
    let corrected = corrected_json(model, options, &corrections, &mut notes)?;
    let verdict: Vec<String> = if state.named.is_empty() {
        vec!["none".to_string()]
    } else {
        state.named.iter().map(|k| k.name().to_string()).collect()
    };

    Ok(Diagnosis {
        model: ModelSummary {
            name: model.name.clone(),
            kind: model.kind_name().to_string(),
            file: model.source.file.clone(),
            sha256: model.source.sha256.clone(),
            gravity: base.gravity,
        },
        logs: summaries(train, &data.raw, false),
        holdout: holdout_summary(&problem, train, holdout, split, inside),
        effects,
        verdict,
        shrink,
        reference,
        where_report,
        rounds: rounds_report,
        corrections,
        corrected,
        notes,
        warnings,
        response_times,
        options: options.clone(),
    })
}

/// The physical checks' findings ([`physical`]): candidates left out for them, the final state's
/// linear effects (after backfitting), and the command channels' slow-down.
fn physical_warnings(
    problem: &problem::Problem,
    state: &problem::State,
    rounds: &[select::Round],
    times: &[response_time::ChannelTime],
) -> Vec<String> {
    let mut out = Vec::new();
    for (r, round) in rounds.iter().enumerate() {
        for c in &round.candidates {
            let physical: Vec<&String> = c
                .reasons
                .iter()
                .filter(|m| m.starts_with("implausible: ") || m.starts_with("not identifiable: "))
                .collect();
            // Only where the physical check decided: the candidate passed every other rule.
            if !physical.is_empty() && physical.len() == c.reasons.len() {
                for m in physical {
                    out.push(format!("round {}: {} not named — {m}", r + 1, c.kind));
                }
            }
        }
    }
    let fin = problem.final_fit();
    if !state.linear.is_empty() {
        let g = problem.ctx.gravity;
        for (_, m) in physical::implausible_all(&state.linear, &state.theta[fin], g) {
            out.push(format!("the named effects after backfitting: {m}"));
        }
        let cur = problem::current(problem, state);
        for c in physical::cancelling(
            &|s, f| cur.chunks(problem, s, &state.linear, f),
            &problem.fits[fin].train,
            &problem.mask,
            &state.linear,
            &state.theta[fin],
            None,
        ) {
            out.push(format!("the named effects after backfitting: {}", c.sentence()));
        }
    }
    out.extend(physical::slowdowns(times));
    out
}

/// The prepared training (and held-out) data; an error when either has no usable segment.
fn prepare_data<'a>(
    base: &residuals::Base,
    options: &DiagnoseOptions,
    train: &'a [FlightLog],
    holdout: &'a [FlightLog],
    split: usize,
    progress: &mut dyn FnMut(Progress),
) -> Result<data::Prepared<'a>, DiagnoseError> {
    progress(Progress {
        done: 0,
        total: 0,
        what: "preparing the data",
    });
    let data = data::prepare(base, &options.savgol, options.residual, train, holdout, split)?;
    let rows = options.savgol.window + 2;
    if !data.raw.iter().any(|s| !s.holdout) {
        return Err(DiagnoseError::NoData {
            what: "the training logs".into(),
            rows,
        });
    }
    if !holdout.is_empty() && !data.raw.iter().any(|s| s.holdout) {
        return Err(DiagnoseError::NoData {
            what: "the held-out logs".into(),
            rows,
        });
    }
    Ok(data)
}

/// Where: the report on the base model's residuals on the training logs (when asked for). The
/// analysis input (the residual series and the samples, ~230 bytes per training sample) is not
/// kept: the report holds what the plots draw ([`crate::analysis::write_plots`]).
fn where_analysis(
    base: &residuals::Base,
    ctx: Context,
    data: &data::Prepared,
    train: &[FlightLog],
    options: &DiagnoseOptions,
    progress: &mut dyn FnMut(Progress),
) -> Option<WhereReport> {
    options.where_analysis.then(|| {
        progress(Progress {
            done: 0,
            total: 0,
            what: "where: residual analysis",
        });
        let segs: Vec<&data::SegData> = data.raw.iter().filter(|s| !s.holdout).collect();
        let input = where_link::where_input(&Augmented::plain(base, ctx), &segs, options.horizon, train);
        where_link::where_report(&input, options.horizon)
    })
}

/// How far the gap shrinks on the held-out data of every test fit, and the same on the
/// noise-free copies of the held-out logs (same stretches, same parameters) when given.
fn shrink_figures(
    problem: &problem::Problem,
    state: &problem::State,
    reference: &[FlightLog],
    progress: &mut dyn FnMut(Progress),
) -> Result<(Shrink, Option<ReferenceShrink>), DiagnoseError> {
    let (data, options) = (problem.data, problem.options);
    progress(Progress {
        done: 0,
        total: 0,
        what: "shrink: free runs before and after",
    });
    let (before, after) = shrink::pools(problem, state, false, |s, destaled| Some(&data.variant(destaled)[s]));
    let reference = if reference.is_empty() {
        None
    } else {
        let refdata = data::prepare(problem.base, &options.savgol, options.residual, &[], reference, 1)?;
        let key = |s: &data::SegData| (s.log, s.segment, s.part);
        let (before, after) = shrink::pools(problem, state, true, |s, destaled| {
            let r = refdata.raw.iter().position(|d| key(d) == key(&data.raw[s]))?;
            Some(&refdata.variant(destaled)[r])
        });
        Some(ReferenceShrink {
            data: "the held-out flights logged without sensor noise".to_string(),
            before,
            after,
        })
    };
    let shrink = Shrink::new(
        if problem.cv {
            format!(
                "cross-validation: each of {} folds' held-out segments, parameters fitted on the others",
                problem.fits.len() - 1
            )
        } else {
            "held-out logs".to_string()
        },
        state.named.iter().map(|k| k.name().to_string()).collect(),
        options.horizon,
        before,
        after,
        ClosedLoop {
            status: "not run".to_string(),
            plant: options.plant.as_ref().map(|p| p.display().to_string()),
            note: "give a plant file (`--plant`) to fly the base and the corrected model in closed loop".to_string(),
            verdict: None,
            runs: Vec::new(),
        },
    );
    Ok((shrink, reference))
}

/// Which held-out data scored the candidates.
fn holdout_summary(
    problem: &problem::Problem,
    train: &[FlightLog],
    holdout: &[FlightLog],
    split: usize,
    inside: f64,
) -> Holdout {
    let cv = problem.cv;
    Holdout {
        mode: if cv { "cross-validation" } else { "logs" }.to_string(),
        logs: summaries(holdout, &problem.data.raw, true),
        folds: if cv { problem.fits.len() - 1 } else { 1 },
        description: if !cv {
            "fitted on the training logs, scored on the held-out logs".to_string()
        } else if train.len() >= 2 {
            "leave one training log out".to_string()
        } else if split > 1 {
            format!("the lone training segment cut into {split} consecutive parts, leave one part out")
        } else {
            "leave one training segment out".to_string()
        },
        scored_fraction: inside,
    }
}

/// corrected.json: the model file with the corrections block (null, with a note, when the model
/// text is not at hand: see `Diagnosis::corrected_from`).
fn corrected_json(
    model: &Model,
    options: &DiagnoseOptions,
    corrections: &Corrections,
    notes: &mut Vec<String>,
) -> Result<serde_json::Value, DiagnoseError> {
    let text = options
        .model_text
        .clone()
        .or_else(|| std::fs::read_to_string(&model.source.file).ok());
    Ok(match &text {
        Some(t) => corrected_value(t, &model.source.file, corrections)?,
        None => {
            notes.push(format!(
                "corrected.json needs the model file's text ({} not found from here): pass \
                 DiagnoseOptions::model_text or call Diagnosis::corrected_from",
                model.source.file
            ));
            serde_json::Value::Null
        }
    })
}
