//! `uavgen identify`: flight logs → a `uavgen-model/1` file (SINDy or PD).

use clap::{Args, ValueEnum};
use std::path::PathBuf;
use uavgen::evaluate::{horizon_score, EvaluateOptions};
use uavgen::identify::bounded_selection::select_bounded_with;
use uavgen::identify::dataset::{build, DatasetOptions, Targets};
use uavgen::identify::excitation::{self, Excitation, ExcitationOptions};
use uavgen::identify::horizon_check::{self, HorizonCheck};
use uavgen::identify::horizon_delay::{self, HeldOut, RefineOptions};
use uavgen::identify::loop_refine;
use uavgen::identify::pd::{self, PdFitOptions};
use uavgen::identify::preprocess::{LowPass, SavGol};
use uavgen::identify::response::{self, InputResponse, ScanOptions, ScanSegment};
use uavgen::identify::sindy::{
    self, AicSelection, Criterion, FittedRows, LibraryKind, Optimizer, Regularizer, SindyOptions,
};
use uavgen::logs::stale::StalePolicy;
use uavgen::model::envelope;

#[derive(Clone, Copy, ValueEnum)]
pub enum Method {
    /// Sparse regression on a candidate library (docs/sindy.md).
    Sindy,
    /// The paper's 16-parameter PD/Euler-Lagrange model (docs/pd-fit.md).
    Pd,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum LibraryArg {
    /// The paper's Θ = [1, x, u, x², x·u, sin Ω, cos Ω, x sin Ω, x cos Ω] (155 terms).
    Paper,
    /// Kinematic rows exact, no raw position or yaw (translation and heading invariance).
    Physics,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum OptimizerArg {
    Stlsq,
    Sr3L0,
    Sr3L1,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum CriterionArg {
    Aic,
    Bic,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RefineLoopsArg {
    /// Refine each loop's row by its held-out free runs; kept where they improve by 5 %.
    Auto,
    /// Keep the sparse regression's coefficients.
    None,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TargetsArg {
    Derivative,
    Integral,
}

#[derive(Args)]
pub struct IdentifyArgs {
    /// Identification method.
    #[arg(long, value_enum)]
    method: Method,
    /// Flight log (docs/log-format.md CSV, or a recording imported with --profile); repeat for several.
    #[arg(long = "log", required = true)]
    logs: Vec<PathBuf>,
    /// How to read --log files that are not CSV (PX4 ULog, …): a preset (px4, mavros,
    /// dji-osdk-ros, ardupilot) or a profile file (docs/import.md).
    #[arg(long)]
    profile: Option<String>,
    /// Output model file.
    #[arg(long)]
    out: PathBuf,
    /// Model name (default: the output file's stem).
    #[arg(long)]
    name: Option<String>,
    /// Overwrite --out if it exists.
    #[arg(long)]
    force: bool,
    /// Savitzky-Golay window (odd, samples) for derivatives. Default: the odd sample count nearest
    /// 0.3 s at the logs' sample period (the slowest log's median; 9 at 30 Hz, 15 at 50 Hz, 31 at
    /// 100 Hz).
    #[arg(long)]
    savgol_window: Option<usize>,
    /// Savitzky-Golay polynomial order.
    #[arg(long, default_value_t = 3)]
    savgol_order: usize,
    /// SINDy: candidate library.
    #[arg(long, value_enum, default_value_t = LibraryArg::Physics)]
    library: LibraryArg,
    /// SINDy: fit all 12 rows (the paper) instead of the 6 dynamic rows with exact kinematics.
    #[arg(long)]
    all_rows: bool,
    /// SINDy: optimiser.
    #[arg(long, value_enum, default_value_t = OptimizerArg::Stlsq)]
    optimizer: OptimizerArg,
    /// SINDy: one sparsity parameter (STLSQ threshold on normalised coefficients, SR3 λ) instead
    /// of the default sweep. Without it (and with --sweep) the sparsity is swept and selected.
    #[arg(long)]
    threshold: Option<f64>,
    /// SINDy: sweep the sparsity parameter and select by the criterion (the default unless
    /// --threshold is given; with --threshold, SR3's sweep is scaled by it).
    #[arg(long)]
    sweep: bool,
    /// SINDy: the sweep's values (comma separated). Default: STLSQ thresholds 0.5 … 256 in steps of
    /// √2; SR3 λ = --threshold (0.05) × 0.1, 0.2, 0.5, 1, 2, 4, 8, 16.
    #[arg(long, value_delimiter = ',')]
    sweep_values: Option<Vec<f64>>,
    /// SINDy, STLSQ: the ridge weight α of each least-squares pass (on normalised columns). Default:
    /// the ridge ladder 0.001, 0.01, 0.1 — the first α whose selection passes the horizon check. A
    /// larger α shrinks nearly collinear term pairs (large coefficients of opposite sign that cancel
    /// on the logs and explode off them) so the threshold can drop them (docs/sindy.md).
    #[arg(long)]
    alpha: Option<f64>,
    /// Write the model even if it fails the horizon check (one MPC horizon of free run from random
    /// envelope states under constant, often saturated, inputs must stay bounded).
    #[arg(long)]
    no_horizon_check: bool,
    /// SINDy: criterion of the sweep (per row, effective sample count).
    #[arg(long, value_enum, default_value_t = CriterionArg::Bic)]
    criterion: CriterionArg,
    /// Input delays: `auto` (default) estimates each channel's delay (0 … 0.5 s; a best delay
    /// within one sample of 0.5 s is refused with a warning, a channel that carries no signal is
    /// not scanned: no delay) and, where it
    /// improves held-out free runs, a first-order lag (0.02 … 0.8 s) from the logs, then refines
    /// each delay by the refitted model's held-out free runs over one horizon (kept where both
    /// held-out ends improve by 5 %), and writes them as `corrections.latency` /
    /// `corrections.actuator_lag`; `none` fits the inputs as logged; or
    /// seconds for every input, or per channel `u_vz=0.13,u_roll=0.08,…` (the others 0), no lags.
    #[arg(long, default_value = "auto")]
    input_delay: String,
    /// Stale rows (the state repeats the previous row's, sample-and-hold telemetry): `interpolate`
    /// (default) treats them as missing samples and interpolates their states before
    /// differentiating; `keep` uses the log as recorded (docs/logs.md).
    #[arg(long, value_enum, default_value_t = StalePolicy::Interpolate)]
    stale: StalePolicy,
    /// The regression's targets (default: `integral` for SINDy, `derivative` for PD). `integral`:
    /// the integral form over each sample interval, (x_{k+1} − x_k)/Δt against the trapezoid mean
    /// of the SINDy library (PD: the model at the interval's midpoint state), no differentiation;
    /// `derivative`: Savitzky-Golay derivatives at the samples (docs/sindy.md, "Targets").
    #[arg(long, value_enum)]
    targets: Option<TargetsArg>,
    /// SINDy: refine the rows the commands drive (vz, roll_rate, pitch_rate, yaw_rate) by
    /// simulation error: their selected terms' coefficients are fitted to free runs of one MPC
    /// horizon on the logs (roll and pitch judged by the angle), cross-validated over the logs
    /// and kept where the held-out free runs improve by 5 % (`auto`, the default; integral
    /// targets only); `none` keeps the sparse regression's coefficients
    /// (docs/identification.md, "Loop refinement").
    #[arg(long, value_enum, default_value_t = RefineLoopsArg::Auto)]
    refine_loops: RefineLoopsArg,
    /// PD: mass in kg.
    #[arg(long, default_value_t = 2.4)]
    mass: f64,
    /// PD: the paper's first-order low-pass λ/(s+λ) with this λ in rad/s (the paper: 1).
    #[arg(long)]
    lowpass: Option<f64>,
}

/// The default STLSQ sweep: thresholds on normalised columns (they scale like √N, docs/sindy.md),
/// 0.5 … 256 in steps of √2 (the bounded selection needs sparse values to move rows to).
fn stlsq_sweep() -> Vec<f64> {
    (0..=18)
        .map(|i| 0.5 * 2f64.powf(i as f64 / 2.0))
        .map(|v| (v * 1e3).round() / 1e3)
        .collect()
}
/// The default SR3 sweep, as multiples of --threshold.
const SR3_SWEEP: [f64; 8] = [0.1, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0];

const INPUTS: [&str; 4] = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"];

/// What `--input-delay` asks for.
enum DelaySpec {
    Auto,
    None,
    List([f64; 4]),
}

fn parse_delay_spec(spec: &str) -> Result<DelaySpec, String> {
    match spec.trim() {
        "auto" => Ok(DelaySpec::Auto),
        "none" => Ok(DelaySpec::None),
        _ => parse_input_delay(spec).map(DelaySpec::List),
    }
}

/// The longest input delay `--input-delay` accepts, s (as a plant's latency).
const MAX_INPUT_DELAY_S: f64 = uavgen::sim::plant_file::MAX_DELAY_S;

/// `0.1` (every input) or `u_vz=0.13,u_roll=0.08` (the others 0), in seconds.
fn parse_input_delay(spec: &str) -> Result<[f64; 4], String> {
    let bad = |what: &str| format!("--input-delay '{spec}': {what}");
    let check = |v: f64| {
        if v.is_finite() && (0.0..=MAX_INPUT_DELAY_S).contains(&v) {
            Ok(v)
        } else {
            Err(bad(&format!(
                "delays must be within [0, {MAX_INPUT_DELAY_S}] s, found {}",
                uavgen::validate::short(v)
            )))
        }
    };
    if let Ok(v) = spec.trim().parse::<f64>() {
        return Ok([check(v)?; 4]);
    }
    let mut out = [0.0; 4];
    for part in spec.split(',') {
        let (name, value) = part
            .split_once('=')
            .ok_or_else(|| bad("expected auto, none, seconds, or name=seconds pairs separated by commas"))?;
        let j = INPUTS.iter().position(|n| *n == name.trim()).ok_or_else(|| {
            bad(&format!(
                "unknown input '{}' (inputs: {})",
                name.trim(),
                INPUTS.join(", ")
            ))
        })?;
        out[j] = check(
            value
                .trim()
                .parse()
                .map_err(|_| bad(&format!("'{}' is not a number", value.trim())))?,
        )?;
    }
    Ok(out)
}

fn check_positive(name: &str, v: f64) -> Result<(), String> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(format!("--{name}: must be a positive number, got {v}"))
    }
}

/// The round-trip-safe value written to the model file (0.1 ms).
fn round_s(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

/// Estimate the input response from the logs (`--input-delay auto`).
/// The scan always works on the integral form (`h` = 0: no derivative window), whatever targets the
/// fit uses (docs/sindy.md, "Targets").
fn estimate_response(
    logs: &[uavgen::logs::FlightLog],
    savgol: SavGol,
    ex: &Excitation,
) -> Result<response::ResponseEstimate, String> {
    let whole = build(
        logs,
        &DatasetOptions {
            savgol,
            trim_edges: false,
            targets: Targets::Trapezoid,
            ..DatasetOptions::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let segments: Vec<ScanSegment> = whole
        .segments
        .into_iter()
        .map(|s| ScanSegment {
            log: s.log,
            dt: s.dt,
            h: 0,
            x: s.x,
            u: s.u,
            dx: s.dx,
            x_next: s.x_next,
        })
        .collect();
    let options = ScanOptions {
        silent: ex.silent(),
        excluded_vars: ex.excluded_vars(),
        ..ScanOptions::default()
    };
    response::estimate(&segments, &options).map_err(|e| e.to_string())
}

pub fn run(args: IdentifyArgs) -> Result<(), String> {
    super::refuse_existing(&args.out, args.force)?;
    let name = args
        .name
        .clone()
        .or_else(|| args.out.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "identified".into());
    // An explicit window is checked before any work; the default needs the logs' rate.
    let check_savgol =
        |w: usize| SavGol::new(w, args.savgol_order).map_err(|e| format!("--savgol-window/--savgol-order: {e}"));
    if let Some(w) = args.savgol_window {
        check_savgol(w)?;
    }
    let delay_spec = parse_delay_spec(&args.input_delay)?;
    // Every value is checked before any work (the PD options too, which are used last).
    if matches!(args.method, Method::Pd) {
        check_positive("mass", args.mass)?;
        if let Some(lambda) = args.lowpass {
            check_positive("lowpass", lambda)?;
        }
    }
    if let Some(t) = args.threshold {
        if !(t.is_finite() && t >= 0.0) {
            return Err(format!("--threshold: must be a finite number >= 0, got {t}"));
        }
    }
    if let Some(a) = args.alpha.filter(|a| !(a.is_finite() && (0.0..=1e6).contains(a))) {
        return Err(format!("--alpha: must be a number in 0 … 1e6, got {a}"));
    }
    if args.alpha.is_some() && !matches!((&args.method, &args.optimizer), (Method::Sindy, OptimizerArg::Stlsq)) {
        return Err("--alpha: the ridge weight of SINDy's STLSQ; not with --method pd or an SR3 optimiser".into());
    }
    if args.sweep_values.is_some() && !args.sweep && args.threshold.is_some() {
        return Err("--sweep-values: not with --threshold (a single sparsity value) unless --sweep is given".into());
    }
    if let Some(v) = &args.sweep_values {
        if v.is_empty() || v.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
            return Err(format!(
                "--sweep-values: every value must be a finite number >= 0, got {v:?}"
            ));
        }
    }
    let mut logs = Vec::new();
    for path in &args.logs {
        let log = uavgen::logs::load_any(path, args.profile.as_deref()).map_err(|e| e.to_string())?;
        for w in log.report.warnings() {
            eprintln!("warning: {}: {w}", path.display());
        }
        let (stale, rows) = (log.report.stale_states(), log.rows());
        if stale > 0 {
            eprintln!(
                "{}: {stale} of {rows} rows stale (state repeats the previous row): {}",
                path.display(),
                match args.stale {
                    StalePolicy::Interpolate => "interpolated (--stale interpolate)",
                    StalePolicy::Keep => "kept as logged (--stale keep)",
                }
            );
        }
        logs.push(log.with_stale(args.stale));
    }
    // Degenerate data is an error: with every state and input constant (an all-zero log, a
    // vehicle on the ground) there is nothing to fit, and the fit would have no terms.
    if logs.iter().all(constant_log) {
        return Err(format!(
            "{}: every state and input column is constant (an all-zero log, or a vehicle that never moved): there is nothing to identify",
            args.logs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
        ));
    }
    // Everything rate-dependent is set in seconds and converted at the logs' sample period.
    let dt = sample_period(&logs).unwrap_or(1.0 / 30.0);
    let savgol = check_savgol(args.savgol_window.unwrap_or_else(|| savgol_window(dt)))?;
    // Directions the logs did not excite (docs/identification.md, "Unexcited directions").
    let excitation_options = ExcitationOptions::default();
    let ex = excitation::analyse(&logs, &excitation_options);
    let mut warnings = ex.warnings();
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let targets = match (args.targets, &args.method) {
        (Some(TargetsArg::Integral), _) | (None, Method::Sindy) => Targets::Trapezoid,
        (Some(TargetsArg::Derivative), _) | (None, Method::Pd) => Targets::SavGol,
    };
    let (response, estimate) = match delay_spec {
        DelaySpec::None => (None, None),
        DelaySpec::List(d) => (
            Some(InputResponse {
                delay: d,
                lag: [None; 4],
            }),
            None,
        ),
        DelaySpec::Auto => {
            eprintln!(
                "estimating input delays and lags (--input-delay auto: delays 0..0.5 s, lags 0.02..0.8 s; held-out one-step error of the driven row, guarded by its loop's held-out free runs) ..."
            );
            let est = super::progress::with_spinner("estimating input delays and lags", || {
                estimate_response(&logs, savgol, &ex)
            })?;
            eprintln!(
                "  held out: {} {}; per channel: delay (Δχ² = 1 range), lag, one-step and loop free-run RMSE before -> after",
                est.folds, est.fold_kind
            );
            for c in &est.channels {
                eprintln!("  {}", c.line());
            }
            for c in &est.channels {
                if let Some(d) = c.refused_at_edge {
                    let w = format!(
                        "{}: the delay estimate {d:.3} s lies at the edge of the 0..{} s scan (the response may lie beyond it, or the data hold no minimum): refused, no delay",
                        c.input,
                        ScanOptions::default().max_delay
                    );
                    eprintln!("warning: {w}");
                    warnings.push(w);
                }
            }
            let refined = refine_delays(&args, &logs, &est.response, savgol, targets, &ex, dt);
            let response = refined.as_ref().map_or(est.response, |r| r.response);
            (Some(response), Some((est, refined)))
        }
    };
    let dataset = build(
        &logs,
        &DatasetOptions {
            savgol,
            response,
            targets,
            ..DatasetOptions::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let files: Vec<String> = args.logs.iter().map(|p| p.display().to_string()).collect();
    let mut provenance = serde_json::json!({
        "tool": format!("uavgen {} identify", env!("CARGO_PKG_VERSION")),
        "logs": files,
        "samples": dataset.len(),
        "savitzky_golay": { "window": savgol.window, "order": savgol.order, "window_s": savgol.window as f64 * dt },
        "sample_period": dt,
        "excitation": ex.to_json(&excitation_options),
        "stale": args.stale.name(),
        "input_delay": args.input_delay.trim(),
        "targets": match targets {
            Targets::SavGol => "derivative",
            Targets::Trapezoid => "integral",
        },
    });
    if let Some((est, refined)) = &estimate {
        provenance["input_response"] = input_response_json(est, refined.as_ref());
    }
    // With the loop refinement kept, the sparse fit's own text is the fallback should the refined
    // model fail the horizon check.
    let mut unrefined = None;
    let json = match args.method {
        Method::Sindy => {
            let fitted = fit_sindy(&args, &dataset, logs.len(), &name, provenance, response, &ex)?;
            match refine_loops(&args, &fitted, &dataset, dt)? {
                Some(texts) => {
                    unrefined = texts.fallback;
                    texts.chosen
                }
                None => fitted,
            }
        }
        Method::Pd => {
            let options = pd_options(&args, &ex)?;
            eprintln!(
                "fitting the PD model on {} samples from {} log(s) ...",
                dataset.len(),
                logs.len()
            );
            let fit = super::progress::with_spinner("fitting the PD model", || {
                pd::fit(&dataset, &options, &name, provenance)
            })
            .map_err(|e| e.to_string())?;
            eprintln!("{}", fit.diagnostics.summary());
            serde_json::to_string_pretty(&fit.file).map_err(|e| e.to_string())?
        }
    } + "\n";
    let refs: Vec<&uavgen::logs::FlightLog> = logs.iter().collect();
    let envelope = envelope::from_logs(&refs);
    if let Some(e) = &envelope {
        eprintln!(
            "operating envelope (observed range of the logs, widened): {}",
            e.bounds
                .iter()
                .map(|(s, lo, hi)| format!("{s} [{lo}, {hi}]"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let (mut json, chosen, model) = checked(&json, unrefined.as_deref(), &args, response, envelope.as_ref(), &ex)?;
    // A commanded channel the model does not act on (docs/identification.md, "Zero gains").
    warnings.extend(gain_warnings(&model, &ex));
    if !warnings.is_empty() {
        let with = add_warnings(&chosen, &args, &warnings)?;
        json = finish(&with, &args, response, envelope.as_ref())?.0;
    }
    super::write_atomically(&args.out, &json)?;
    println!("wrote {}", args.out.display());
    Ok(())
}

/// `provenance.input_response`: what `--input-delay auto` found per channel, and the refinement
/// over the horizon.
fn input_response_json(
    est: &response::ResponseEstimate,
    refined: Option<&horizon_delay::Refinement>,
) -> serde_json::Value {
    let channels: serde_json::Map<String, serde_json::Value> = est
        .channels
        .iter()
        .map(|c| {
            (
                c.input.to_string(),
                serde_json::json!({
                    "delay": round_s(c.delay),
                    "delay_range": [round_s(c.delay_range.0), round_s(c.delay_range.1)],
                    "lag": c.lag.map(round_s),
                    "lag_range": c.lag_range.map(|(a, b)| [round_s(a), round_s(b)]),
                    "held_out_one_step_rmse": [c.one_step_rmse.0, c.one_step_rmse.1],
                    "held_out_horizon_rmse": [c.horizon_rmse.0, c.horizon_rmse.1, c.horizon_rmse.2],
                    "evidence": c.evidence,
                    "note": c.note,
                    "silent": c.silent,
                    "refused_at_edge": c.refused_at_edge.map(round_s),
                }),
            )
        })
        .collect();
    let mut v = serde_json::json!({
        "held_out": format!("{} {}", est.folds, est.fold_kind),
        "channels": channels,
    });
    if let Some(r) = refined {
        v["refined_over_the_horizon"] = refinement_json(r, &RefineOptions::default());
    }
    v
}

/// The text to write: `json` as [`finish`] makes it, its corrections printed, and the horizon check
/// (one MPC horizon of free run from random envelope states must stay bounded). When the model
/// fails it and `unrefined` (the sparse fit before the loop refinement) is given, that one is
/// checked instead; a model that still fails is an error unless --no-horizon-check.
fn checked(
    json: &str,
    unrefined: Option<&str>,
    args: &IdentifyArgs,
    response: Option<InputResponse>,
    envelope: Option<&envelope::DeclaredEnvelope>,
    ex: &Excitation,
) -> Result<(String, String, uavgen::model::Model), String> {
    let mut chosen = json.to_string();
    let (mut json, mut model) = finish(json, args, response, envelope)?;
    if let Some(c) = model.corrections.as_ref() {
        for line in c.summary(&model.inputs) {
            eprintln!("  corrections: {}", line.trim());
        }
    }
    let check_options = horizon_check_options(ex);
    let mut report = super::progress::with_spinner("horizon check", || horizon_check::check(&model, &check_options));
    if let (Some(r), Some(text)) = (&report, unrefined) {
        if !r.passed() {
            eprintln!(
                "loop refinement: the refined model leaves the bounds within one MPC horizon ({} of {} trials); keeping the sparse fit's coefficients",
                r.unbounded, r.trials
            );
            (json, model) = finish(text, args, response, envelope)?;
            chosen = text.to_string();
            report = horizon_check::check(&model, &check_options);
        }
    }
    if let Some(report) = report {
        eprintln!("{}", report.summary());
        if !report.passed() && !args.no_horizon_check {
            return Err(format!(
                "{}: not written: the identified model leaves the bounds within one MPC horizon ({} of {} trials); \
                 give sparser --sweep-values (or a larger --threshold), or pass --no-horizon-check to write it anyway",
                args.out.display(),
                report.unbounded,
                report.trials
            ));
        }
    }
    Ok((json, chosen, model))
}

/// The horizon check of `identify`: the defaults, with the start yaw within the logged arc when
/// the heading did not move (docs/identification.md, "Unexcited directions").
fn horizon_check_options(ex: &Excitation) -> HorizonCheck {
    HorizonCheck {
        yaw: ex.heading_still.then(|| ex.yaw_range()).flatten(),
        ..HorizonCheck::default()
    }
}

/// The default Savitzky-Golay window at sample period `dt`: the odd sample count nearest
/// [`SAVGOL_WINDOW_S`], at least 5 (the smallest window of the default order 3). It is not widened
/// for a higher --savgol-order: an order the window cannot carry is an error naming both flags.
fn savgol_window(dt: f64) -> usize {
    let n = response::samples(SAVGOL_WINDOW_S, dt);
    let n = if n % 2 == 0 { n + 1 } else { n };
    n.max(5)
}

/// The default Savitzky-Golay window, s (9 samples at 30 Hz).
const SAVGOL_WINDOW_S: f64 = 0.3;

/// Warnings for the commanded channels the model does not act on: a static gain below
/// [`excitation::ZERO_GAIN`] (docs/identification.md, "Zero gains"). A silent channel whose terms
/// were left out is said so.
fn gain_warnings(model: &uavgen::model::Model, ex: &Excitation) -> Vec<String> {
    let Some(gains) = excitation::channel_gains(model) else {
        return Vec::new();
    };
    let silent = ex.silent();
    let mut out = Vec::new();
    for (input, g) in excitation::zero_gains(&gains, [true; 4]) {
        let j = INPUTS.iter().position(|n| *n == input).unwrap_or(0);
        let w = if silent[j] {
            format!("{input}: the model does not act on it (static gain {g:.3}): the logs carry no signal on this channel, so the model cannot predict its effect")
        } else {
            format!("{input}: the identified static gain is ~0 ({g:.3}, below {}): the model ignores a command the logs carry", excitation::ZERO_GAIN)
        };
        eprintln!("warning: {w}");
        out.push(w);
    }
    out
}

/// The fit's text (before corrections and envelope) with `provenance.warnings`.
fn add_warnings(text: &str, args: &IdentifyArgs, warnings: &[String]) -> Result<String, String> {
    fn put(p: &mut serde_json::Value, warnings: &[String]) {
        if let serde_json::Value::Object(m) = p {
            m.insert("warnings".into(), serde_json::json!(warnings));
        }
    }
    match args.method {
        Method::Sindy => {
            let mut f: uavgen::model::SindyFile = serde_json::from_str(text).map_err(|e| e.to_string())?;
            put(&mut f.provenance, warnings);
            serde_json::to_string_pretty(&f).map_err(|e| e.to_string())
        }
        Method::Pd => {
            let mut f: uavgen::model::PdFile = serde_json::from_str(text).map_err(|e| e.to_string())?;
            put(&mut f.provenance, warnings);
            serde_json::to_string_pretty(&f).map_err(|e| e.to_string())
        }
    }
    .map(|t| t + "\n")
}

/// The model text as it will be written (corrections and envelope attached) and what `--model`
/// will read from it, validated.
fn finish(
    json: &str,
    args: &IdentifyArgs,
    response: Option<InputResponse>,
    envelope: Option<&envelope::DeclaredEnvelope>,
) -> Result<(String, uavgen::model::Model), String> {
    let json = attach(json, args, response)?;
    let json = match envelope {
        Some(e) => envelope::attach(&json, &args.out.display().to_string(), e).map_err(|e| e.to_string())?,
        None => json,
    };
    let model = uavgen::model::parse(&json, &args.out.display().to_string())
        .map_err(|e| format!("the identified model is invalid: {e}"))?;
    Ok((json, model))
}

/// What [`refine_loops`] gives: the text to write (the refinement recorded in its provenance) and,
/// when a loop was refined, the sparse fit's text to fall back on (its provenance saying so).
struct RefinedTexts {
    chosen: String,
    fallback: Option<String>,
}

/// `--refine-loops auto`: the simulation-error refinement of the loops' rows
/// (`uavgen::identify::loop_refine`), printed and recorded in the provenance
/// (`provenance.loop_refinement`). `None` when it does not run (`none`, or derivative targets).
fn refine_loops(
    args: &IdentifyArgs,
    fitted: &str,
    dataset: &uavgen::identify::dataset::Dataset,
    dt: f64,
) -> Result<Option<RefinedTexts>, String> {
    if args.refine_loops == RefineLoopsArg::None {
        return Ok(None);
    }
    if !dataset.is_interval_form() {
        eprintln!("loop refinement: skipped (it needs the integral targets, --targets integral)");
        return Ok(None);
    }
    let sparse: uavgen::model::SindyFile = serde_json::from_str(fitted).map_err(|e| e.to_string())?;
    let mut file = sparse.clone();
    let options = loop_refine::RefineOptions::for_period(dt);
    eprintln!(
        "refining the loops by simulation error (--refine-loops auto: free runs of {} samples every {} samples, at most {} runs, held out by log; kept at a {:.0} % held-out gain) ...",
        options.horizon,
        options.stride,
        options.max_windows,
        100.0 * options.min_gain
    );
    let report = super::progress::with_spinner("refining the loops", || {
        loop_refine::refine(&mut file.coefficients, dataset, &options)
    });
    for r in &report {
        eprintln!("  {}", r.line());
    }
    let loops: serde_json::Map<String, serde_json::Value> = report
        .iter()
        .map(|r| {
            (
                r.row.to_string(),
                serde_json::json!({
                    "judged_by": r.output,
                    "held_out_free_run_rmse": [r.held_out_rmse.0, r.held_out_rmse.1],
                    "kept": r.kept,
                    "sparse_fit": r.terms.iter().map(|(t, a, _)| (t.clone(), serde_json::json!(a))).collect::<serde_json::Map<_, _>>(),
                    "note": r.note,
                }),
            )
        })
        .collect();
    let record = serde_json::json!({
        "horizon": options.horizon,
        "stride": options.stride,
        "horizon_s": loop_refine::HORIZON_S,
        "stride_s": loop_refine::STRIDE_S,
        "max_windows": options.max_windows,
        "min_gain": options.min_gain,
        "loops": loops,
    });
    let text = |mut f: uavgen::model::SindyFile, record: serde_json::Value| -> Result<String, String> {
        if let serde_json::Value::Object(p) = &mut f.provenance {
            p.insert("loop_refinement".into(), record);
        }
        serde_json::to_string_pretty(&f).map_err(|e| e.to_string())
    };
    let fallback = if report.iter().any(|r| r.kept) {
        let mut reverted = record.clone();
        reverted["reverted"] = "the refined model failed the horizon check: the sparse fit's coefficients".into();
        Some(text(sparse, reverted)? + "\n")
    } else {
        None
    };
    Ok(Some(RefinedTexts {
        chosen: text(file, record)?,
        fallback,
    }))
}

/// Is every state and input of `log` constant (within 1e-12)?
fn constant_log(log: &uavgen::logs::FlightLog) -> bool {
    let mut first: Option<([f64; 12], [f64; 4])> = None;
    log.segments.iter().all(|seg| {
        seg.x.iter().zip(&seg.u).all(|(x, u)| {
            let (x0, u0) = *first.get_or_insert((*x, *u));
            x.iter()
                .zip(&x0)
                .chain(u.iter().zip(&u0))
                .all(|(a, b)| (a - b).abs() <= 1e-12)
        })
    })
}

/// The ridge weights `identify` tries in turn without --alpha (docs/sindy.md, "Ridge ladder").
const RIDGE_LADDER: [f64; 3] = [1e-3, 1e-2, 1e-1];

/// The PD fit's options of `args`.
fn pd_options(args: &IdentifyArgs, ex: &Excitation) -> Result<PdFitOptions, String> {
    check_positive("mass", args.mass)?;
    let mut options = PdFitOptions {
        mass: args.mass,
        unit_gain: ex.silent(),
        ..PdFitOptions::default()
    };
    if let Some(lambda) = args.lowpass {
        check_positive("lowpass", lambda)?;
        options.lowpass = Some(LowPass { lambda });
    }
    Ok(options)
}

/// The second stage of `--input-delay auto` ([`horizon_delay`]): each channel's delay chosen by the
/// held-out free runs of the model refitted on 80 % of every segment (its first and its last 20 %
/// held out in turn). `None` (and a
/// line saying why) when the logs are too short to hold a part out or the one-step response
/// cannot be scored.
fn refine_delays(
    args: &IdentifyArgs,
    logs: &[uavgen::logs::FlightLog],
    start: &InputResponse,
    savgol: SavGol,
    targets: Targets,
    ex: &Excitation,
    dt: f64,
) -> Option<horizon_delay::Refinement> {
    let options = RefineOptions {
        fixed: ex.silent(),
        ..RefineOptions::default()
    };
    let min_rows = options.min_rows(dt);
    let splits: Vec<_> = [HeldOut::Tail, HeldOut::Head]
        .into_iter()
        .map(|end| horizon_delay::split_logs(logs, options.train_share, min_rows, end))
        .collect();
    if splits.iter().any(|(_, test)| test.is_empty()) {
        eprintln!(
            "  delays not refined over the horizon: no segment is long enough to hold out {:.0} % of it ({} s; the one-step delays are kept)",
            100.0 * (1.0 - options.train_share),
            options.min_part
        );
        return None;
    }
    let evaluate_options = EvaluateOptions {
        horizon: response::samples(REFINE_HORIZON_S, dt),
        dataset: DatasetOptions {
            savgol,
            ..DatasetOptions::default()
        },
        stale: args.stale,
        ..EvaluateOptions::default()
    };
    // Per split: the held-out horizon RMSE of the model refitted with `r` (free runs every
    // `stride`-th sample, horizon_delay::SCORE_SPACING_S).
    let stride = horizon_delay::score_stride(dt);
    let split_rmse = |r: &InputResponse, (train, test): &(Vec<_>, Vec<_>)| -> Option<f64> {
        let model = candidate_model(args, train, r, savgol, targets, ex)?;
        let e = horizon_score(&model, test, &evaluate_options, stride).ok()?;
        // A candidate whose free runs diverge is not a better model, whatever its finite runs say.
        (e.diverged == 0).then_some(e.overall_rmse?)
    };
    // The worse split's RMSE relative to the start's (the first call scores the start).
    let mut reference: Option<Vec<f64>> = None;
    let mut score = |r: &InputResponse| -> Option<f64> {
        let rmse: Vec<f64> = splits.iter().map(|sp| split_rmse(r, sp)).collect::<Option<_>>()?;
        let base = reference.get_or_insert_with(|| rmse.clone());
        rmse.iter().zip(base.iter()).map(|(a, b)| a / b).reduce(f64::max)
    };
    let refined = super::progress::with_spinner("refining the delays over the horizon", || {
        horizon_delay::refine(start, dt, &options, &mut score)
    });
    match &refined {
        Some(r) => {
            eprintln!(
                "  delays refined over the horizon (model refitted on {:.0} % of every segment, free runs of {} samples starting {} sample(s) apart on the rest, its first and its last part in turn; score: the worse part's overall RMSE relative to the one-step delays'): {:.3} -> {:.3}",
                100.0 * options.train_share,
                evaluate_options.horizon,
                stride,
                r.before,
                r.after
            );
            for c in &r.channels {
                eprintln!(
                    "  {:<10} delay {:.3} s -> {:.3} s (tried {})",
                    c.input,
                    c.one_step,
                    c.delay,
                    c.scores
                        .iter()
                        .map(|(d, s)| format!("{d:.3}: {s:.4}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
        }
        None => eprintln!(
            "  delays not refined over the horizon: the model with the one-step delays could not be fitted or its held-out free runs diverged (the one-step delays are kept)"
        ),
    }
    refined
}

/// The free runs of the delay refinement, s (one MPC horizon).
const REFINE_HORIZON_S: f64 = 1.0;

/// The sample period at which `identify` converts its durations to samples: the slowest log's
/// (the largest of the logs' median periods). With logs of one rate that is their period; the
/// M100's runs at 0.030 s and 0.0333 s give 0.0333 s (30 Hz).
fn sample_period(logs: &[uavgen::logs::FlightLog]) -> Option<f64> {
    logs.iter()
        .filter_map(|l| median_period(std::slice::from_ref(l)))
        .reduce(f64::max)
}

/// The median sample period over every segment of `logs`.
fn median_period(logs: &[uavgen::logs::FlightLog]) -> Option<f64> {
    let steps: Vec<f64> = logs
        .iter()
        .flat_map(|l| &l.segments)
        .flat_map(|s| s.t.windows(2).map(|w| w[1] - w[0]))
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    uavgen::logs::median(&steps)
}

/// The model `identify` would fit on `logs` with the input response `r`, quietly and without the
/// horizon check or the ridge ladder (its first rung): a candidate of the delay refinement.
fn candidate_model(
    args: &IdentifyArgs,
    logs: &[uavgen::logs::FlightLog],
    r: &InputResponse,
    savgol: SavGol,
    targets: Targets,
    ex: &Excitation,
) -> Option<uavgen::model::Model> {
    let dataset = build(
        logs,
        &DatasetOptions {
            savgol,
            response: Some(*r),
            targets,
            ..DatasetOptions::default()
        },
    )
    .ok()?;
    let file = match args.method {
        Method::Sindy => {
            let alpha = args.alpha.unwrap_or(RIDGE_LADDER[0]);
            let options = sindy_options(args, alpha, sindy_sweep(args), ex);
            let fit = sindy::fit_with_progress(&dataset, &options, "candidate", serde_json::json!({}), &mut |_, _| {})
                .ok()?;
            serde_json::to_string(&fit.file).ok()?
        }
        Method::Pd => {
            let fit = pd::fit(
                &dataset,
                &pd_options(args, ex).ok()?,
                "candidate",
                serde_json::json!({}),
            )
            .ok()?;
            serde_json::to_string(&fit.file).ok()?
        }
    };
    let text = attach(&file, args, Some(*r)).ok()?;
    uavgen::model::parse(&text, "candidate model").ok()
}

/// The refinement (made with `options`) for the model's provenance.
fn refinement_json(r: &horizon_delay::Refinement, options: &RefineOptions) -> serde_json::Value {
    let channels: serde_json::Map<String, serde_json::Value> = r
        .channels
        .iter()
        .map(|c| {
            (
                c.input.to_string(),
                serde_json::json!({
                    "one_step": round_s(c.one_step),
                    "delay": round_s(c.delay),
                    "scores": c.scores.iter().map(|(d, s)| serde_json::json!([round_s(*d), if s.is_finite() { serde_json::json!(s) } else { serde_json::Value::Null }])).collect::<Vec<_>>(),
                }),
            )
        })
        .collect();
    serde_json::json!({
        "held_out": format!("the first and the last {:.0} % of every segment in turn", 100.0 * (1.0 - options.train_share)),
        "score": "the worse held-out part's horizon RMSE relative to the one-step delays'",
        "score_before_after": [r.before, r.after],
        "channels": channels,
    })
}

/// The sparsity values the SINDy fit sweeps (`None`: one value, --threshold).
fn sindy_sweep(args: &IdentifyArgs) -> Option<Vec<f64>> {
    let threshold = args.threshold.unwrap_or(0.05);
    let sweeping = args.sweep || args.threshold.is_none();
    sweeping.then(|| match (&args.sweep_values, args.optimizer) {
        (Some(v), _) => v.clone(),
        (None, OptimizerArg::Stlsq) => stlsq_sweep(),
        (None, _) => SR3_SWEEP.iter().map(|f| threshold.max(1e-3) * f).collect(),
    })
}

/// The SINDy options of `args` with ridge weight `alpha`.
fn sindy_options(args: &IdentifyArgs, alpha: f64, sweep: Option<Vec<f64>>, ex: &Excitation) -> SindyOptions {
    let threshold = args.threshold.unwrap_or(0.05);
    let optimizer = match args.optimizer {
        OptimizerArg::Stlsq => Optimizer::Stlsq {
            threshold,
            alpha,
            max_iter: 20,
            unbias: true,
        },
        OptimizerArg::Sr3L0 => Optimizer::sr3(Regularizer::L0, threshold),
        OptimizerArg::Sr3L1 => Optimizer::sr3(Regularizer::L1, threshold),
    };
    SindyOptions {
        library: match args.library {
            LibraryArg::Paper => LibraryKind::Paper,
            LibraryArg::Physics => LibraryKind::Physics,
        },
        optimizer,
        sweep,
        selection: AicSelection::PerRow,
        criterion: match args.criterion {
            CriterionArg::Aic => Criterion::Aic,
            CriterionArg::Bic => Criterion::Bic,
        },
        rows: if args.all_rows {
            FittedRows::All
        } else {
            FittedRows::Dynamic
        },
        excluded_vars: ex.excluded_vars(),
        ..SindyOptions::default()
    }
}

/// The SINDy fit of `identify`: the sweep, selection by the criterion, then rows moved to sparser
/// values until one MPC horizon stays bounded; without --alpha the ridge ladder is climbed until
/// that succeeds (if no rung does, the one with the fewest unbounded trials is kept, for the
/// caller's check to report).
fn fit_sindy(
    args: &IdentifyArgs,
    dataset: &uavgen::identify::dataset::Dataset,
    logs: usize,
    name: &str,
    provenance: serde_json::Value,
    response: Option<InputResponse>,
    ex: &Excitation,
) -> Result<String, String> {
    let sweep = sindy_sweep(args);
    let ladder: Vec<f64> = match (args.alpha, args.optimizer) {
        (Some(a), _) => vec![a],
        (None, OptimizerArg::Stlsq) if sweep.is_some() && !args.no_horizon_check => RIDGE_LADDER.to_vec(),
        (None, _) => vec![RIDGE_LADDER[0]],
    };
    eprintln!("fitting SINDy on {} samples from {logs} log(s) ...", dataset.len());
    // The fit kept: the first rung that passes, else the one with the fewest unbounded trials.
    let mut fit: Option<(usize, f64, sindy::SindyFit)> = None;
    for (rung, &alpha) in ladder.iter().enumerate() {
        let options = sindy_options(args, alpha, sweep.clone(), ex);
        let bar = super::progress::bar(options.sweep.as_ref().map_or(1, Vec::len), "sparsity values");
        let mut f = sindy::fit_with_progress(dataset, &options, name, provenance.clone(), &mut |done, _| {
            bar.set_position(done as u64)
        })
        .map_err(|e| e.to_string())?;
        bar.finish_and_clear();
        let mut unbounded = 0;
        if options.sweep.is_some() && !args.no_horizon_check {
            let check = horizon_check_options(ex);
            let with = |fit: &sindy::SindyFit| attach(&fit.to_json(), args, response);
            let selection = super::progress::with_spinner(&format!("horizon check (ridge α = {alpha})"), || {
                select_bounded_corrected(&mut f, &check, &with)
            });
            if let Some(sel) = selection {
                for (row, from, to) in &sel.moves {
                    eprintln!("  horizon check: {row} moved from sparsity {from} to {to}");
                }
                unbounded = sel.report.unbounded;
                if unbounded > 0 && rung + 1 < ladder.len() {
                    eprintln!(
                        "  ridge α = {alpha}: {} of {} horizon-check trials still unbounded; refitting with α = {}",
                        sel.report.unbounded,
                        sel.report.trials,
                        ladder[rung + 1]
                    );
                }
            }
        }
        let better = match &fit {
            None => true,
            Some((u, _, _)) => unbounded < *u,
        };
        if better {
            fit = Some((unbounded, alpha, f));
        }
        if unbounded == 0 {
            if ladder.len() > 1 {
                eprintln!("  ridge α = {alpha} (the first of {ladder:?} whose selection passes the horizon check)");
            }
            break;
        }
    }
    let (unbounded, alpha, fit) = fit.ok_or("no SINDy fit")?;
    if unbounded > 0 && ladder.len() > 1 {
        eprintln!(
            "  ridge α: no rung of {ladder:?} passes the horizon check; keeping α = {alpha} (the fewest unbounded trials, {unbounded})"
        );
    }
    for row in &fit.rows {
        eprintln!(
            "  {:<10} {:>3} terms, training RMSE {:.4}, R² {:.3}",
            row.state, row.terms, row.rmse, row.r2
        );
    }
    if fit.rows.iter().all(|r| r.terms == 0) {
        return Err(format!(
            "{}: not written: the fit selected no term in any row (the logs do not excite the dynamics, or --threshold is too large)",
            args.out.display()
        ));
    }
    serde_json::to_string_pretty(&fit.file).map_err(|e| e.to_string())
}

/// The model text with the input response as `corrections` (latency, actuator_lag).
fn attach(json: &str, args: &IdentifyArgs, response: Option<InputResponse>) -> Result<String, String> {
    let Some(r) = response.filter(|r| !r.is_identity()) else {
        return Ok(json.to_string());
    };
    let latency = INPUTS
        .iter()
        .zip(r.delay)
        .filter(|(_, d)| round_s(*d) > 0.0)
        .map(|(n, d)| (n.to_string(), round_s(d)))
        .collect();
    let actuator_lag = INPUTS
        .iter()
        .zip(r.lag)
        .filter_map(|(n, l)| l.map(|t| (n.to_string(), round_s(t))))
        .collect();
    let source = match parse_delay_spec(&args.input_delay) {
        Ok(DelaySpec::Auto) => {
            "uavgen identify --input-delay auto: delays and lags estimated from the logs; the model was fitted to the inputs they give"
        }
        _ => "uavgen identify --input-delay: the model was fitted to u(t - delay)",
    };
    let corrections = uavgen::model::Corrections {
        source: Some(source.into()),
        latency,
        actuator_lag,
        ..Default::default()
    };
    uavgen::model::attach_corrections(json, &args.out.display().to_string(), &corrections).map_err(|e| e.to_string())
}

/// [`select_bounded`] on the model as it will be written (with its corrections).
fn select_bounded_corrected(
    fit: &mut sindy::SindyFit,
    check: &HorizonCheck,
    with: &dyn Fn(&sindy::SindyFit) -> Result<String, String>,
) -> Option<uavgen::identify::bounded_selection::BoundedSelection> {
    select_bounded_with(fit, &|f| {
        let text = with(f).ok()?;
        let model = uavgen::model::parse(&text, "identified model").ok()?;
        horizon_check::check(&model, check)
    })
}
