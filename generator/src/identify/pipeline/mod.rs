//! Identification from flight logs to a `uavgen-model/1` text: the whole of `uavgen identify` as a
//! library function, so that the CLI and the Python package are two thin front ends of one code
//! path (docs/identification.md).
//!
//! The stages, in order (each documented in docs/identification.md):
//! 1. the logs' quality report and stale rows ([`StalePolicy`]), degenerate data refused;
//! 2. durations in seconds converted at the logs' sample period ([`sample_period`]);
//! 3. the directions the logs did not excite ([`excitation`]);
//! 4. `input_delay = "auto"`: the delay/lag scan ([`response`]) and the delays refined over the
//!    horizon ([`horizon_delay`]) — [`delays`];
//! 5. the fit: SINDy's sweep × ridge ladder × bounded selection and the loop refinement
//!    ([`sindy_fit`]), or the PD model ([`pd`]);
//! 6. corrections, envelope, the horizon check and the zero-gain warnings ([`output`]).
//!
//! Messages go to a [`Report`]: the CLI prints them on stderr and draws bars on a terminal; Python
//! collects them.

mod delays;
mod output;
mod pd_fit;
mod sindy_fit;

use super::dataset::{build, DatasetOptions, Targets};
use super::excitation::{self, ExcitationOptions};
use super::pd::PdFitOptions;
use super::preprocess::{LowPass, SavGol};
use super::response::{self, InputResponse};
use super::sindy::{Criterion, LibraryKind};
use crate::logs::resample;
use crate::logs::stale::StalePolicy;
use crate::logs::FlightLog;
use crate::model::envelope;

/// The identification method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Sparse regression on a candidate library (docs/sindy.md).
    Sindy,
    /// The paper's 16-parameter PD/Euler-Lagrange model (docs/pd-fit.md).
    Pd,
}

/// SINDy's optimiser.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OptimizerChoice {
    Stlsq,
    Sr3L0,
    Sr3L1,
}

/// Everything `uavgen identify` takes besides the logs and the output path; the fields are its
/// flags (`--savgol-window` is `savgol_window`, `--no-horizon-check` is `horizon_check = false`),
/// [`IdentifyOptions::new`] its defaults. `uavgen identify --help` documents each.
#[derive(Clone, Debug)]
pub struct IdentifyOptions {
    pub method: Method,
    /// The model's name (the CLI: --name, else the output file's stem).
    pub name: String,
    /// How the output is named in messages (the CLI: --out's path).
    pub out_label: String,
    pub savgol_window: Option<usize>,
    pub savgol_order: usize,
    pub library: LibraryKind,
    pub all_rows: bool,
    pub optimizer: OptimizerChoice,
    pub threshold: Option<f64>,
    pub sweep: bool,
    pub sweep_values: Option<Vec<f64>>,
    pub alpha: Option<f64>,
    /// Refuse a model that leaves the bounds within one MPC horizon (the CLI's default; false is
    /// --no-horizon-check).
    pub horizon_check: bool,
    pub criterion: Criterion,
    /// `auto`, `none`, seconds, or `u_vz=0.13,u_roll=0.08,…`.
    pub input_delay: String,
    pub stale: StalePolicy,
    /// `None`: integral targets for SINDy, derivative targets for PD.
    pub targets: Option<Targets>,
    /// The loop refinement (`--refine-loops auto`): SINDy's command loops, PD's attitude loops.
    pub refine_loops: bool,
    /// PD: mass, kg.
    pub mass: f64,
    /// PD: the paper's low-pass λ, rad/s.
    pub lowpass: Option<f64>,
    /// Logs at least twice this fast (Hz) are low-passed and decimated towards it before anything
    /// else ([`resample`]); the CLI's --max-rate.
    pub max_rate_hz: f64,
}

impl IdentifyOptions {
    /// The CLI's defaults for `method`, the model named `name`.
    pub fn new(method: Method, name: &str) -> Self {
        IdentifyOptions {
            method,
            name: name.to_string(),
            out_label: name.to_string(),
            savgol_window: None,
            savgol_order: 3,
            library: LibraryKind::Physics,
            all_rows: false,
            optimizer: OptimizerChoice::Stlsq,
            threshold: None,
            sweep: false,
            sweep_values: None,
            alpha: None,
            horizon_check: true,
            criterion: Criterion::Bic,
            input_delay: "auto".into(),
            stale: StalePolicy::Interpolate,
            targets: None,
            refine_loops: true,
            mass: 2.4,
            lowpass: None,
            max_rate_hz: resample::DEFAULT_MAX_RATE_HZ,
        }
    }

    /// Every value checked before any work (the PD options too, which are used last).
    pub fn validate(&self) -> Result<(), String> {
        if let Some(w) = self.savgol_window {
            self.savgol(w)?;
        }
        parse_delay_spec(&self.input_delay)?;
        if self.method == Method::Pd {
            check_positive("mass", self.mass)?;
            if let Some(lambda) = self.lowpass {
                check_positive("lowpass", lambda)?;
            }
        }
        check_positive("max-rate", self.max_rate_hz)?;
        if let Some(t) = self.threshold {
            if !(t.is_finite() && t >= 0.0) {
                return Err(format!("--threshold: must be a finite number >= 0, got {t}"));
            }
        }
        if let Some(a) = self.alpha.filter(|a| !(a.is_finite() && (0.0..=1e6).contains(a))) {
            return Err(format!("--alpha: must be a number in 0 … 1e6, got {a}"));
        }
        if self.alpha.is_some() && !(self.method == Method::Sindy && self.optimizer == OptimizerChoice::Stlsq) {
            return Err("--alpha: the ridge weight of SINDy's STLSQ; not with --method pd or an SR3 optimiser".into());
        }
        if self.sweep_values.is_some() && !self.sweep && self.threshold.is_some() {
            return Err(
                "--sweep-values: not with --threshold (a single sparsity value) unless --sweep is given".into(),
            );
        }
        if let Some(v) = &self.sweep_values {
            if v.is_empty() || v.iter().any(|x| !(x.is_finite() && *x >= 0.0)) {
                return Err(format!(
                    "--sweep-values: every value must be a finite number >= 0, got {v:?}"
                ));
            }
        }
        Ok(())
    }

    /// The Savitzky-Golay filter of `window` samples at --savgol-order.
    fn savgol(&self, window: usize) -> Result<SavGol, String> {
        SavGol::new(window, self.savgol_order).map_err(|e| format!("--savgol-window/--savgol-order: {e}"))
    }

    /// The regression's targets: integral for SINDy, derivative for PD unless chosen.
    fn targets(&self) -> Targets {
        match (self.targets, self.method) {
            (Some(t), _) => t,
            (None, Method::Sindy) => Targets::Trapezoid,
            (None, Method::Pd) => Targets::SavGol,
        }
    }

    /// The PD fit's options.
    fn pd_options(&self, ex: &excitation::Excitation) -> Result<PdFitOptions, String> {
        check_positive("mass", self.mass)?;
        let mut options = PdFitOptions {
            mass: self.mass,
            unit_gain: ex.silent(),
            ..PdFitOptions::default()
        };
        if let Some(lambda) = self.lowpass {
            check_positive("lowpass", lambda)?;
            options.lowpass = Some(LowPass { lambda });
        }
        Ok(options)
    }
}

/// Where identification's messages go. The CLI prints lines on stderr and draws a bar or spinner
/// (on a terminal) between [`Report::begin`] and [`Report::end`].
pub trait Report {
    /// A line of progress or results (warnings start with `warning: `).
    fn line(&self, text: &str);
    /// Long work begins: `steps` of it when known (a bar), else of unknown length (a spinner).
    fn begin(&self, _what: &str, _steps: Option<usize>) {}
    /// `done` steps of the work begun are done.
    fn advance(&self, _done: usize) {}
    /// The work begun has ended.
    fn end(&self) {}
}

/// A [`Report`] that drops everything.
pub struct Quiet;

impl Report for Quiet {
    fn line(&self, _text: &str) {}
}

/// Run `work` between `begin(what)` and `end()`.
fn stage<T>(report: &dyn Report, what: &str, work: impl FnOnce() -> T) -> T {
    report.begin(what, None);
    let out = work();
    report.end();
    out
}

/// The model identified: the text to write, the model it parses to, and the warnings (also in its
/// `provenance.warnings`).
#[derive(Clone, Debug)]
pub struct Identified {
    pub json: String,
    pub model: crate::model::Model,
    pub warnings: Vec<String>,
}

const INPUTS: [&str; 4] = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"];

/// What `input_delay` asks for.
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

/// The longest input delay `input_delay` accepts, s (as a plant's latency).
const MAX_INPUT_DELAY_S: f64 = crate::sim::plant_file::MAX_DELAY_S;

/// `0.1` (every input) or `u_vz=0.13,u_roll=0.08` (the others 0), in seconds.
fn parse_input_delay(spec: &str) -> Result<[f64; 4], String> {
    let bad = |what: &str| format!("--input-delay '{spec}': {what}");
    let check = |v: f64| {
        if v.is_finite() && (0.0..=MAX_INPUT_DELAY_S).contains(&v) {
            Ok(v)
        } else {
            Err(bad(&format!(
                "delays must be within [0, {MAX_INPUT_DELAY_S}] s, found {}",
                crate::validate::short(v)
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

/// The default Savitzky-Golay window, s (9 samples at 30 Hz).
const SAVGOL_WINDOW_S: f64 = 0.3;

/// The default Savitzky-Golay window at sample period `dt`: the odd sample count nearest
/// [`SAVGOL_WINDOW_S`], at least 5 (the smallest window of the default order 3). It is not widened
/// for a higher --savgol-order: an order the window cannot carry is an error naming both flags.
pub fn savgol_window(dt: f64) -> usize {
    let n = response::samples(SAVGOL_WINDOW_S, dt);
    let n = if n % 2 == 0 { n + 1 } else { n };
    n.max(5)
}

/// The sample period at which `identify` converts its durations to samples: the slowest log's
/// (the largest of the logs' median periods). With logs of one rate that is their period; the
/// M100's runs at 0.030 s and 0.0333 s give 0.0333 s (30 Hz).
pub fn sample_period(logs: &[FlightLog]) -> Option<f64> {
    logs.iter()
        .filter_map(|l| median_period(std::slice::from_ref(l)))
        .reduce(f64::max)
}

/// The median sample period over every segment of `logs`.
fn median_period(logs: &[FlightLog]) -> Option<f64> {
    let steps: Vec<f64> = logs
        .iter()
        .flat_map(|l| &l.segments)
        .flat_map(|s| s.t.windows(2).map(|w| w[1] - w[0]))
        .filter(|d| d.is_finite() && *d > 0.0)
        .collect();
    crate::logs::median(&steps)
}

/// Is every state and input of `log` constant (within 1e-12)?
fn constant_log(log: &FlightLog) -> bool {
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

/// The logs as the fit sees them: each one's quality warnings and stale rows said, the stale
/// policy applied (in place), then resampled to `max_rate_hz` if at least twice as fast (said, and
/// returned for the provenance).
fn prepared_logs(
    logs: Vec<FlightLog>,
    stale: StalePolicy,
    max_rate_hz: f64,
    report: &dyn Report,
) -> (Vec<FlightLog>, Vec<serde_json::Value>) {
    let mut resampled = Vec::new();
    let logs = logs
        .into_iter()
        .map(|log| {
            for w in log.report.warnings() {
                report.line(&format!("warning: {}: {w}", log.source));
            }
            let (n, rows) = (log.report.stale_states(), log.rows());
            if n > 0 {
                report.line(&format!(
                    "{}: {n} of {rows} rows stale (state repeats the previous row): {}",
                    log.source,
                    match stale {
                        StalePolicy::Interpolate => "interpolated (--stale interpolate)",
                        StalePolicy::Keep => "kept as logged (--stale keep)",
                    }
                ));
            }
            let (log, note) = resample::for_identification(log, stale, max_rate_hz);
            if let Some(note) = note {
                report.line(&note.to_string());
                resampled.push(note.to_json());
            }
            log
        })
        .collect();
    (logs, resampled)
}

/// Identify a model from `logs` (as loaded: [`crate::logs::load_any`]) with `options`: the text
/// `uavgen identify` writes. Errors are the CLI's messages. The logs are taken by value: the stale
/// rows are interpolated in place and each log is dropped once nothing needs it (docs/identification.md,
/// "Memory").
pub fn identify(logs: Vec<FlightLog>, options: &IdentifyOptions, report: &dyn Report) -> Result<Identified, String> {
    options.validate()?;
    let delay_spec = parse_delay_spec(&options.input_delay)?;
    let (logs, resampled) = prepared_logs(logs, options.stale, options.max_rate_hz, report);
    // Degenerate data is an error: with every state and input constant (an all-zero log, a
    // vehicle on the ground) there is nothing to fit, and the fit would have no terms.
    if logs.iter().all(constant_log) {
        return Err(format!(
            "{}: every state and input column is constant (an all-zero log, or a vehicle that never moved): there is nothing to identify",
            logs.iter().map(|l| l.source.as_str()).collect::<Vec<_>>().join(", ")
        ));
    }
    // Everything rate-dependent is set in seconds and converted at the logs' sample period.
    let dt = sample_period(&logs).unwrap_or(1.0 / 30.0);
    let savgol = options.savgol(options.savgol_window.unwrap_or_else(|| savgol_window(dt)))?;
    // Directions the logs did not excite (docs/identification.md, "Unexcited directions").
    let excitation_options = ExcitationOptions::default();
    let ex = excitation::analyse(&logs, &excitation_options);
    let mut warnings = ex.warnings();
    for w in &warnings {
        report.line(&format!("warning: {w}"));
    }
    let targets = options.targets();
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
            let (response, est, refined) =
                delays::auto(options, &logs, savgol, targets, &ex, dt, &mut warnings, report)?;
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
    let files: Vec<&str> = logs.iter().map(|l| l.source.as_str()).collect();
    let mut provenance = serde_json::json!({
        "tool": format!("uavgen {} identify", env!("CARGO_PKG_VERSION")),
        "logs": files,
        "samples": dataset.len(),
        "savitzky_golay": { "window": savgol.window, "order": savgol.order, "window_s": savgol.window as f64 * dt },
        "sample_period": dt,
        "excitation": ex.to_json(&excitation_options),
        "stale": options.stale.name(),
        "input_delay": options.input_delay.trim(),
        "targets": match targets {
            Targets::SavGol => "derivative",
            Targets::Trapezoid => "integral",
        },
    });
    if !resampled.is_empty() {
        provenance["resampled"] = serde_json::Value::Array(resampled);
    }
    if let Some((est, refined)) = &estimate {
        provenance["input_response"] = delays::input_response_json(est, refined.as_ref());
    }
    // The operating envelope is the logs' last use but PD's integral form: taken now, so that the
    // logs are dropped before the fit (said after it, as ever).
    let envelope = envelope::from_logs(&logs.iter().collect::<Vec<&FlightLog>>());
    let log_count = logs.len();
    // With the loop refinement kept, the sparse fit's own text is the fallback should the refined
    // model fail the horizon check.
    let mut unrefined = None;
    let json = match options.method {
        Method::Sindy => {
            drop(logs);
            let fitted = sindy_fit::fit(options, &dataset, log_count, provenance, response, &ex, report)?;
            match sindy_fit::refine_loops(options, &fitted, &dataset, dt, report)? {
                Some(texts) => {
                    unrefined = texts.fallback;
                    texts.chosen
                }
                None => fitted,
            }
        }
        Method::Pd => {
            let (text, fallback) = pd_fit::fit(options, logs, &dataset, savgol, response, &ex, dt, provenance, report)?;
            unrefined = fallback.map(|t| t + "\n");
            text
        }
    } + "\n";
    drop(dataset);
    if let Some(e) = &envelope {
        report.line(&format!(
            "operating envelope (observed range of the logs, widened): {}",
            e.bounds
                .iter()
                .map(|(s, lo, hi)| format!("{s} [{lo}, {hi}]"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    let out = output::Output {
        options,
        response,
        envelope: envelope.as_ref(),
    };
    let (mut json, chosen, model) = out.checked(&json, unrefined.as_deref(), &ex, report)?;
    // A commanded channel the model does not act on (docs/identification.md, "Zero gains").
    warnings.extend(output::gain_warnings(&model, &ex, report));
    if !warnings.is_empty() {
        let with = out.add_warnings(&chosen, &warnings)?;
        json = out.finish(&with)?.0;
    }
    Ok(Identified { json, model, warnings })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_savgol_window_is_about_0_3_s_at_any_rate() {
        assert_eq!(savgol_window(1.0 / 30.0), 9);
        assert_eq!(savgol_window(1.0 / 50.0), 15);
        assert_eq!(savgol_window(1.0 / 100.0), 31);
        // Never below the smallest window of order 3.
        assert_eq!(savgol_window(0.5), 5);
    }

    #[test]
    fn input_delay_specs() {
        assert!(matches!(parse_delay_spec(" auto "), Ok(DelaySpec::Auto)));
        assert!(matches!(parse_delay_spec("none"), Ok(DelaySpec::None)));
        assert!(matches!(parse_delay_spec("0.1"), Ok(DelaySpec::List(d)) if d == [0.1; 4]));
        assert!(
            matches!(parse_delay_spec("u_roll=0.08, u_vz=0.13"), Ok(DelaySpec::List(d)) if d == [0.13, 0.08, 0.0, 0.0])
        );
        let e = parse_input_delay("u_thrust=0.1").unwrap_err();
        assert!(e.contains("unknown input 'u_thrust'"), "{e}");
        let e = parse_input_delay("-0.1").unwrap_err();
        assert!(e.contains("within [0,"), "{e}");
    }

    #[test]
    fn options_are_checked_before_any_work() {
        let ok = IdentifyOptions::new(Method::Sindy, "m");
        assert!(ok.validate().is_ok());
        let e = IdentifyOptions {
            alpha: Some(0.1),
            ..IdentifyOptions::new(Method::Pd, "m")
        }
        .validate()
        .unwrap_err();
        assert!(e.starts_with("--alpha"), "{e}");
        let e = IdentifyOptions {
            mass: -1.0,
            ..IdentifyOptions::new(Method::Pd, "m")
        }
        .validate()
        .unwrap_err();
        assert!(e.starts_with("--mass"), "{e}");
        let e = IdentifyOptions {
            savgol_window: Some(4),
            ..ok.clone()
        }
        .validate()
        .unwrap_err();
        assert!(e.starts_with("--savgol-window"), "{e}");
    }

    #[test]
    fn a_constant_log_is_refused_naming_it() {
        let n = 50;
        let log = FlightLog {
            source: "still.csv".into(),
            metadata: Vec::new(),
            segments: vec![crate::logs::Segment {
                index: 0,
                t: (0..n).map(|k| k as f64 / 30.0).collect(),
                x: vec![[0.0; 12]; n],
                u: vec![[0.0; 4]; n],
                battery_voltage: None,
                first_line: 2,
            }],
            report: crate::logs::QualityReport {
                source: "still.csv".into(),
                rows: n,
                metadata_rate_hz: None,
                measured_period: None,
                nominal_period: None,
                segments: Vec::new(),
            },
        };
        let e = identify(vec![log], &IdentifyOptions::new(Method::Pd, "m"), &Quiet).unwrap_err();
        assert!(
            e.starts_with("still.csv: every state and input column is constant"),
            "{e}"
        );
    }
}
