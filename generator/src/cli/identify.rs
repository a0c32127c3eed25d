//! `uavgen identify`: flight logs → a `uavgen-model/1` file (SINDy or PD).

//!
//! A thin front end: the options become [`IdentifyOptions`], the logs are read, and
//! [`uavgen::identify::pipeline::identify`] does the work (the Python package calls the same).

use clap::{Args, ValueEnum};
use std::cell::RefCell;
use std::path::PathBuf;
use uavgen::identify::dataset::Targets;
use uavgen::identify::pipeline::{self, IdentifyOptions, OptimizerChoice, Report};
use uavgen::identify::sindy::{Criterion, LibraryKind};
use uavgen::logs::stale::StalePolicy;

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
    /// Refine the loops the commands drive by simulation error: fitted to free runs of one MPC
    /// horizon on the logs (roll and pitch judged by the angle), cross-validated over the logs
    /// and kept where the held-out free runs improve by 5 % (`auto`, the default). SINDy: the
    /// selected terms' coefficients of vz, roll_rate, pitch_rate, yaw_rate (integral targets
    /// only); PD: the attitude loops' gain, stiffness and damping ξ2, ξ5, ξ8 and ξ3, ξ6, ξ9,
    /// within the fit's bounds. `none` keeps the regression's coefficients
    /// (docs/identification.md, "Loop refinement").
    #[arg(long, value_enum, default_value_t = RefineLoopsArg::Auto)]
    refine_loops: RefineLoopsArg,
    /// PD: mass in kg.
    #[arg(long, default_value_t = 2.4)]
    mass: f64,
    /// PD: the paper's first-order low-pass λ/(s+λ) with this λ in rad/s (the paper: 1).
    #[arg(long)]
    lowpass: Option<f64>,
    /// Logs at least twice this fast (Hz) are low-passed (delay-free) and decimated to the largest
    /// whole factor keeping at least this rate, with a note (a 1 kHz log → 100 Hz; docs/logs.md,
    /// "Resampling").
    #[arg(long, default_value_t = uavgen::logs::resample::DEFAULT_MAX_RATE_HZ)]
    max_rate: f64,
}

impl IdentifyArgs {
    /// The library's options of these flags.
    fn options(&self) -> IdentifyOptions {
        let method = match self.method {
            Method::Sindy => pipeline::Method::Sindy,
            Method::Pd => pipeline::Method::Pd,
        };
        let name = self
            .name
            .clone()
            .or_else(|| self.out.file_stem().map(|s| s.to_string_lossy().into_owned()))
            .unwrap_or_else(|| "identified".into());
        IdentifyOptions {
            out_label: self.out.display().to_string(),
            savgol_window: self.savgol_window,
            savgol_order: self.savgol_order,
            library: match self.library {
                LibraryArg::Paper => LibraryKind::Paper,
                LibraryArg::Physics => LibraryKind::Physics,
            },
            all_rows: self.all_rows,
            optimizer: match self.optimizer {
                OptimizerArg::Stlsq => OptimizerChoice::Stlsq,
                OptimizerArg::Sr3L0 => OptimizerChoice::Sr3L0,
                OptimizerArg::Sr3L1 => OptimizerChoice::Sr3L1,
            },
            threshold: self.threshold,
            sweep: self.sweep,
            sweep_values: self.sweep_values.clone(),
            alpha: self.alpha,
            horizon_check: !self.no_horizon_check,
            criterion: match self.criterion {
                CriterionArg::Aic => Criterion::Aic,
                CriterionArg::Bic => Criterion::Bic,
            },
            input_delay: self.input_delay.clone(),
            stale: self.stale,
            targets: self.targets.map(|t| match t {
                TargetsArg::Derivative => Targets::SavGol,
                TargetsArg::Integral => Targets::Trapezoid,
            }),
            refine_loops: self.refine_loops == RefineLoopsArg::Auto,
            mass: self.mass,
            lowpass: self.lowpass,
            max_rate_hz: self.max_rate,
            ..IdentifyOptions::new(method, &name)
        }
    }
}

/// Identification's messages on stderr; bars and spinners on a terminal (docs/cli.md, "Progress").
#[derive(Default)]
struct Stderr {
    drawing: RefCell<Option<Drawing>>,
}

/// What is drawn between `begin` and `end`.
enum Drawing {
    Bar(indicatif::ProgressBar),
    // Held for its Drop (it clears the spinner).
    Spinner(#[allow(dead_code)] super::progress::Spinner),
}

impl Report for Stderr {
    fn line(&self, text: &str) {
        eprintln!("{text}");
    }
    fn begin(&self, what: &str, steps: Option<usize>) {
        *self.drawing.borrow_mut() = Some(match steps {
            Some(n) => Drawing::Bar(super::progress::bar(n, what)),
            None => Drawing::Spinner(super::progress::spinner(what)),
        });
    }
    fn advance(&self, done: usize) {
        if let Some(Drawing::Bar(bar)) = &*self.drawing.borrow() {
            bar.set_position(done as u64);
        }
    }
    fn end(&self) {
        if let Some(Drawing::Bar(bar)) = self.drawing.borrow_mut().take() {
            bar.finish_and_clear();
        }
    }
}

pub fn run(args: IdentifyArgs) -> Result<(), String> {
    super::refuse_existing(&args.out, args.force)?;
    let options = args.options();
    // Every value is checked before any work.
    options.validate()?;
    let mut logs = Vec::new();
    for path in &args.logs {
        logs.push(uavgen::logs::load_any(path, args.profile.as_deref()).map_err(|e| e.to_string())?);
    }
    let identified = pipeline::identify(logs, &options, &Stderr::default())?;
    super::write_atomically(&args.out, &identified.json)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
