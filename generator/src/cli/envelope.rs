//! `uavgen envelope`: the operating envelope of flight logs, as `uavgen identify` writes it into a
//! model file (docs/model-format.md#envelope), for a model identified without one.

use clap::Args;
use std::path::PathBuf;
use uavgen::model::envelope;

#[derive(Args)]
pub struct EnvelopeArgs {
    /// Model file (uavgen-model/1) the envelope is for.
    #[arg(long)]
    model: PathBuf,
    /// Flight log the model was identified on (CSV, or a recording imported with --profile); repeat for several.
    #[arg(long = "log", required = true)]
    logs: Vec<PathBuf>,
    /// How to read --log files that are not contract CSVs (PX4 ULog, …): a preset (px4, mavros,
    /// dji-osdk-ros, ardupilot) or a profile file; a profile with a `time` column maps a CSV of
    /// another schema (`uavgen import --print-profile csv`; docs/import.md).
    #[arg(long)]
    profile: Option<String>,
    /// Write the model file with this envelope (replacing an `envelope` block it has) here; without
    /// it the envelope is only printed. The coefficients are copied unchanged.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Overwrite --out if it exists (--out may be --model itself).
    #[arg(long)]
    force: bool,
}

pub fn run(args: EnvelopeArgs) -> Result<(), String> {
    if let Some(out) = &args.out {
        super::refuse_existing(out, args.force)?;
    }
    let label = args.model.display().to_string();
    let text = std::fs::read_to_string(&args.model).map_err(|e| format!("{label}: cannot read: {e}"))?;
    let model = uavgen::model::parse(&text, &label).map_err(|e| e.to_string())?;
    let mut logs = Vec::new();
    for path in &args.logs {
        logs.push(uavgen::logs::load_any(path, args.profile.as_deref()).map_err(|e| e.to_string())?);
    }
    let refs: Vec<&uavgen::logs::FlightLog> = logs.iter().collect();
    let observed = envelope::observed(&refs).ok_or("the logs have no rows")?;
    let declared = envelope::widen(&observed);
    println!(
        "operating envelope of {} log(s) ({} rows): observed [min, max] -> declared [lo, hi] \
         (margin {} × half-width + floor; docs/model-format.md#envelope)",
        logs.len(),
        logs.iter().map(|l| l.rows()).sum::<usize>(),
        envelope::MARGIN_FACTOR
    );
    for ((state, min, max), (_, lo, hi)) in observed.iter().zip(&declared.bounds) {
        println!("  {state:<11}[{min:>9.3}, {max:>9.3}] -> [{lo:>9.3}, {hi:>9.3}]");
    }
    if let Some(out) = &args.out {
        let out_text = envelope::attach(&text, &label, &declared).map_err(|e| e.to_string())?;
        // The states the envelope names must be the model's (a standard-state model).
        uavgen::model::parse(&out_text, &label).map_err(|e| e.to_string())?;
        super::write_atomically(out, &out_text)?;
        println!("wrote {} (model '{}' with this envelope)", out.display(), model.name);
    }
    Ok(())
}
