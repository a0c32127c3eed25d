//! `uavgen evaluate`: a model's predictions against flight logs (docs/evaluate.md).

use clap::Args;
use std::path::PathBuf;
use uavgen::evaluate::{evaluate, plot_states, EvaluateOptions};

#[derive(Args)]
pub struct EvaluateArgs {
    /// Model file (uavgen-model/1).
    #[arg(long)]
    model: PathBuf,
    /// Flight log to evaluate on (CSV, or a recording imported with --profile); repeat for several.
    #[arg(long = "log", required = true)]
    logs: Vec<PathBuf>,
    /// How to read --log files that are not contract CSVs (PX4 ULog, …): a preset (px4, mavros,
    /// dji-osdk-ros, ardupilot) or a profile file; a profile with a `time` column maps a CSV of
    /// another schema (`uavgen import --print-profile csv`; docs/import.md).
    #[arg(long)]
    profile: Option<String>,
    /// Free-run horizon in samples (the MPC's; seconds × the log's rate). Its figures come with the
    /// predict-no-change baseline over the same runs (every step predicted as the run's first state).
    #[arg(long, default_value_t = 30)]
    horizon: usize,
    /// RK4 substeps per sample (default: the automatic rule).
    #[arg(long)]
    substeps: Option<usize>,
    /// Also write the full evaluation as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Overwrite --json if it exists (as identify, simulate and track do).
    #[arg(long)]
    force: bool,
    /// Write measured-vs-predicted plots (SVG) into this directory.
    #[arg(long)]
    plots: Option<PathBuf>,
    /// Stale rows (a row whose 12 states repeat the previous row's): `interpolate` treats them as
    /// missing samples (the default, as identify and diagnose do), `keep` uses the log as recorded.
    #[arg(long, value_enum, default_value_t = uavgen::logs::StalePolicy::Interpolate)]
    stale: uavgen::logs::StalePolicy,
}

pub fn run(args: EvaluateArgs) -> Result<(), String> {
    if let Some(path) = &args.json {
        super::refuse_existing(path, args.force)?;
    }
    // Every output is checked before any work, so that a failure leaves nothing behind.
    if let Some(dir) = args.plots.as_ref().filter(|d| d.exists() && !d.is_dir()) {
        return Err(format!("--plots {}: exists and is not a directory", dir.display()));
    }
    let options = EvaluateOptions {
        horizon: args.horizon,
        substeps: args.substeps,
        stale: args.stale,
        ..EvaluateOptions::default()
    };
    uavgen::commands::evaluate::check_options(&options)?;
    let model = uavgen::load(&args.model).map_err(|e| e.to_string())?;
    let mut logs = Vec::new();
    for path in &args.logs {
        let log = super::progress::with_spinner(&format!("reading {}", path.display()), || {
            uavgen::logs::load_any(path, args.profile.as_deref())
        });
        logs.push(log.map_err(|e| e.to_string())?);
    }
    // Cheap and worth knowing: where a log leaves the envelope the model was identified on.
    for note in uavgen::commands::evaluate::envelope_notes(&model, &logs) {
        eprintln!("note: {note}");
    }
    let evaluation =
        super::progress::with_spinner("evaluating (one-step, horizon and whole-flight predictions)", || {
            evaluate(&model, &logs, &options)
        })
        .map_err(|e| e.to_string())?;
    println!("{evaluation}");
    // The plots first, the JSON last: a failed plot leaves no JSON behind.
    if let Some(dir) = &args.plots {
        // The directory and its plots in one critical section: an interrupting signal waits for
        // them (uavgen::interrupt), so no empty or half-filled plot directory is left.
        let _guard = uavgen::interrupt::output_lock();
        std::fs::create_dir_all(dir).map_err(|e| format!("--plots {}: {e}", dir.display()))?;
        for log in &logs {
            let files = super::progress::with_spinner("plotting", || plot_states(&model, log, &options, dir));
            for file in files.map_err(|e| e.to_string())? {
                eprintln!("wrote {}", file.display());
            }
        }
    }
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(&evaluation).map_err(|e| e.to_string())? + "\n";
        super::write_atomically(path, &text)?;
    }
    Ok(())
}
