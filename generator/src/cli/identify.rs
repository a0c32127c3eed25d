//! `uavgen identify`: flight logs → a `uavgen-model/1` file (SINDy or PD).

use clap::{Args, ValueEnum};
use std::path::PathBuf;
use uavgen::identify::bounded_selection::select_bounded;
use uavgen::identify::dataset::{build, DatasetOptions};
use uavgen::identify::horizon_check::{self, HorizonCheck};
use uavgen::identify::pd::{self, PdFitOptions};
use uavgen::identify::preprocess::{LowPass, SavGol};
use uavgen::identify::sindy::{
    self, AicSelection, Criterion, FittedRows, LibraryKind, Optimizer, Regularizer, SindyOptions,
};

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

#[derive(Args)]
pub struct IdentifyArgs {
    /// Identification method.
    #[arg(long, value_enum)]
    method: Method,
    /// Flight log (LOG_FORMAT.md CSV); repeat for several.
    #[arg(long = "log", required = true)]
    logs: Vec<PathBuf>,
    /// Output model file.
    #[arg(long)]
    out: PathBuf,
    /// Model name (default: the output file's stem).
    #[arg(long)]
    name: Option<String>,
    /// Overwrite --out if it exists.
    #[arg(long)]
    force: bool,
    /// Savitzky-Golay window (odd) for derivatives.
    #[arg(long, default_value_t = 9)]
    savgol_window: usize,
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
    /// SINDy: sparsity parameter (STLSQ threshold on normalised coefficients, SR3 λ).
    #[arg(long, default_value_t = 0.05)]
    threshold: f64,
    /// SINDy: sweep the sparsity parameter and select by an information criterion.
    #[arg(long)]
    sweep: bool,
    /// SINDy: the sweep's values (comma separated). Default: STLSQ thresholds 0.5, 1, 2, …, 64;
    /// SR3 λ = --threshold × 0.1, 0.2, 0.5, 1, 2, 4, 8, 16.
    #[arg(long, value_delimiter = ',')]
    sweep_values: Option<Vec<f64>>,
    /// Write the model even if it fails the horizon check (one MPC horizon of free run from random
    /// envelope states under constant, often saturated, inputs must stay bounded).
    #[arg(long)]
    no_horizon_check: bool,
    /// SINDy: criterion of the sweep.
    #[arg(long, value_enum, default_value_t = CriterionArg::Aic)]
    criterion: CriterionArg,
    /// Pure input delay to fit with, written to the model as `corrections.latency` (the runtime
    /// compensates it): seconds for every input, or per channel `u_vz=0.13,u_roll=0.08,…`.
    #[arg(long)]
    input_delay: Option<String>,
    /// PD: mass in kg.
    #[arg(long, default_value_t = 2.4)]
    mass: f64,
    /// PD: the paper's first-order low-pass λ/(s+λ) with this λ in rad/s (the paper: 1).
    #[arg(long)]
    lowpass: Option<f64>,
}

/// The default STLSQ sweep: thresholds on normalised columns (they scale like √N, docs/sindy.md).
const STLSQ_SWEEP: [f64; 8] = [0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0];
/// The default SR3 sweep, as multiples of --threshold.
const SR3_SWEEP: [f64; 8] = [0.1, 0.2, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0];

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress_bar(len: usize, what: &str) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len as u64);
    if let Ok(style) = indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {msg} ({elapsed})") {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    bar
}

const INPUTS: [&str; 4] = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"];

/// `0.1` (every input) or `u_vz=0.13,u_roll=0.08` (the others 0), in seconds.
fn parse_input_delay(spec: &str) -> Result<[f64; 4], String> {
    let bad = |what: &str| format!("--input-delay '{spec}': {what}");
    let check = |v: f64| {
        if v.is_finite() && v >= 0.0 {
            Ok(v)
        } else {
            Err(bad("delays must be finite and >= 0 s"))
        }
    };
    if let Ok(v) = spec.trim().parse::<f64>() {
        return Ok([check(v)?; 4]);
    }
    let mut out = [0.0; 4];
    for part in spec.split(',') {
        let (name, value) = part
            .split_once('=')
            .ok_or_else(|| bad("expected seconds, or name=seconds pairs separated by commas"))?;
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

pub fn run(args: IdentifyArgs) -> Result<(), String> {
    if args.out.exists() && !args.force {
        return Err(format!("{}: exists; pass --force to overwrite it", args.out.display()));
    }
    let name = args
        .name
        .clone()
        .or_else(|| args.out.file_stem().map(|s| s.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "identified".into());
    let savgol = SavGol::new(args.savgol_window, args.savgol_order)
        .map_err(|e| format!("--savgol-window/--savgol-order: {e}"))?;
    let mut logs = Vec::new();
    for path in &args.logs {
        let log = uavgen::logs::read_log(path).map_err(|e| e.to_string())?;
        for w in log.report.warnings() {
            eprintln!("warning: {}: {w}", path.display());
        }
        logs.push(log);
    }
    let input_delay = match &args.input_delay {
        Some(spec) => parse_input_delay(spec)?,
        None => [0.0; 4],
    };
    let dataset = build(
        &logs,
        &DatasetOptions {
            savgol,
            input_delay,
            ..DatasetOptions::default()
        },
    )
    .map_err(|e| e.to_string())?;
    let files: Vec<String> = args.logs.iter().map(|p| p.display().to_string()).collect();
    let provenance = serde_json::json!({
        "tool": format!("uavgen {} identify", env!("CARGO_PKG_VERSION")),
        "logs": files,
        "samples": dataset.len(),
        "savitzky_golay": { "window": savgol.window, "order": savgol.order },
    });
    let json = match args.method {
        Method::Sindy => {
            check_positive("threshold", args.threshold)
                .or_else(|e| if args.threshold == 0.0 { Ok(()) } else { Err(e) })?;
            let optimizer = match args.optimizer {
                OptimizerArg::Stlsq => Optimizer::Stlsq {
                    threshold: args.threshold,
                    alpha: 1e-3,
                    max_iter: 20,
                    unbias: true,
                },
                OptimizerArg::Sr3L0 => Optimizer::sr3(Regularizer::L0, args.threshold),
                OptimizerArg::Sr3L1 => Optimizer::sr3(Regularizer::L1, args.threshold),
            };
            if args.sweep_values.is_some() && !args.sweep {
                return Err("--sweep-values: only with --sweep".into());
            }
            let sweep = args.sweep.then(|| match (&args.sweep_values, args.optimizer) {
                (Some(v), _) => v.clone(),
                (None, OptimizerArg::Stlsq) => STLSQ_SWEEP.to_vec(),
                (None, _) => SR3_SWEEP.iter().map(|f| args.threshold.max(1e-3) * f).collect(),
            });
            let options = SindyOptions {
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
                ..SindyOptions::default()
            };
            eprintln!(
                "fitting SINDy on {} samples from {} log(s) ...",
                dataset.len(),
                logs.len()
            );
            let bar = progress_bar(options.sweep.as_ref().map_or(1, Vec::len), "sparsity values");
            let fit = sindy::fit_with_progress(&dataset, &options, &name, provenance, &mut |done, _| {
                bar.set_position(done as u64)
            })
            .map_err(|e| e.to_string())?;
            bar.finish_and_clear();
            let mut fit = fit;
            if options.sweep.is_some() && !args.no_horizon_check {
                if let Some(sel) = select_bounded(&mut fit, &HorizonCheck::default()) {
                    for (row, from, to) in &sel.moves {
                        eprintln!("  horizon check: {row} moved from sparsity {from} to {to}");
                    }
                }
            }
            for row in &fit.rows {
                eprintln!(
                    "  {:<10} {:>3} terms, training RMSE {:.4}, R² {:.3}",
                    row.state, row.terms, row.rmse, row.r2
                );
            }
            serde_json::to_string_pretty(&fit.file).map_err(|e| e.to_string())?
        }
        Method::Pd => {
            check_positive("mass", args.mass)?;
            let mut options = PdFitOptions {
                mass: args.mass,
                ..PdFitOptions::default()
            };
            if let Some(lambda) = args.lowpass {
                check_positive("lowpass", lambda)?;
                options.lowpass = Some(LowPass { lambda });
            }
            eprintln!(
                "fitting the PD model on {} samples from {} log(s) ...",
                dataset.len(),
                logs.len()
            );
            let fit = pd::fit(&dataset, &options, &name, provenance).map_err(|e| e.to_string())?;
            eprintln!("{}", fit.diagnostics.summary());
            serde_json::to_string_pretty(&fit.file).map_err(|e| e.to_string())?
        }
    } + "\n";
    let json = if input_delay.iter().any(|&d| d > 0.0) {
        let latency = INPUTS
            .iter()
            .zip(input_delay)
            .filter(|(_, d)| *d > 0.0)
            .map(|(n, d)| (n.to_string(), d))
            .collect();
        let corrections = uavgen::model::Corrections {
            source: Some("uavgen identify --input-delay: the model was fitted to u(t - delay)".into()),
            latency,
            ..Default::default()
        };
        uavgen::model::attach_corrections(&json, &args.out.display().to_string(), &corrections)
            .map_err(|e| e.to_string())?
    } else {
        json
    };
    // Exactly what `--model` will read, validated before anything is written.
    let model = uavgen::model::parse(&json, &args.out.display().to_string())
        .map_err(|e| format!("the identified model is invalid: {e}"))?;
    if let Some(report) = horizon_check::check(&model, &HorizonCheck::default()) {
        eprintln!("{}", report.summary());
        if !report.passed() && !args.no_horizon_check {
            return Err(format!(
                "{}: not written: the identified model leaves the bounds within one MPC horizon ({} of {} trials); \
                 raise --threshold (or pick a sparser sweep), or pass --no-horizon-check to write it anyway",
                args.out.display(),
                report.unbounded,
                report.trials
            ));
        }
    }
    super::write_atomically(&args.out, &json)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
