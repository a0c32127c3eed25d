//! `uavgen import`: a PX4 ULog / MCAP / ROS 1 bag / DataFlash file → a flight log CSV of the
//! contract (docs/import.md).

use clap::Args;
use std::path::PathBuf;
use uavgen::import::{import_file, GridOptions, ImportOptions, Profile, PRESETS};

#[derive(Args)]
pub struct ImportArgs {
    /// The recording: PX4 ULog (.ulg), MCAP (.mcap: ROS 2 bags, Foxglove), ROS 1 bag (.bag),
    /// ArduPilot DataFlash (.bin), or a CSV of another schema (with a profile that maps its
    /// columns); the format is taken from the first bytes (docs/import.md). Several files become
    /// consecutive segments of one log.
    #[arg(required_unless_present = "print_profile")]
    files: Vec<PathBuf>,
    /// Topic and field mapping: a preset (px4, mavros, dji-osdk-ros, ardupilot), the CSV template
    /// (csv), or a profile file (uavgen-import-profile/1 JSON; `--print-profile px4` or
    /// `--print-profile csv` prints one to start from).
    #[arg(long, required_unless_present = "print_profile")]
    profile: Option<String>,
    /// Output flight log (docs/log-format.md CSV).
    #[arg(long, required_unless_present = "print_profile")]
    out: Option<PathBuf>,
    /// Rows on a uniform grid at this rate (Hz). Default: at the position topic's own time stamps
    /// (nothing resampled). Every channel is held (zero-order hold) at its latest sample.
    #[arg(long)]
    rate: Option<f64>,
    /// A truncated or damaged file: import what can be read (the rows before a cut; around a
    /// damaged stretch, resuming at the next valid records) instead of failing; each damaged
    /// stretch and the samples and seconds it cost each topic are a warning on stderr and a
    /// `# damaged:` / `# broken:` line in the CSV.
    #[arg(long)]
    partial: bool,
    /// Overwrite --out if it exists.
    #[arg(long)]
    force: bool,
    /// Print a preset profile as JSON and exit (`csv`: the template for a CSV of another schema).
    #[arg(long, value_name = "PRESET")]
    print_profile: Option<String>,
}

pub fn run(args: ImportArgs) -> Result<(), String> {
    if let Some(name) = &args.print_profile {
        if !PRESETS.iter().any(|(n, _)| n == name) {
            return Err(format!(
                "--print-profile: `{name}` is not a preset ({})",
                PRESETS.map(|(n, _)| n).join(", ")
            ));
        }
        let profile = Profile::resolve(name).map_err(|e| e.to_string())?;
        print!("{}", profile.to_json());
        return Ok(());
    }
    let (false, Some(profile), Some(out)) = (args.files.is_empty(), &args.profile, &args.out) else {
        return Err("FILE, --profile and --out are required".into());
    };
    if let Some(hz) = args.rate {
        if !(hz.is_finite() && hz > 0.0) {
            return Err(format!("--rate: must be a positive number of Hz, got {hz}"));
        }
    }
    if out.exists() && !args.force {
        return Err(format!("{}: exists; pass --force to overwrite it", out.display()));
    }
    let profile = Profile::resolve(profile).map_err(|e| e.to_string())?;
    let options = ImportOptions {
        grid: GridOptions { rate_hz: args.rate },
        partial: args.partial,
    };
    let mut imported: Option<uavgen::import::Imported> = None;
    for file in &args.files {
        let next = super::progress::with_spinner(&format!("importing {}", file.display()), || {
            import_file(file, &profile, &options)
        })
        .map_err(|e| e.to_string())?;
        for c in &next.choices {
            eprintln!("{}: {c}", file.display());
        }
        match &mut imported {
            Some(log) => log.append(next),
            None => imported = Some(next),
        }
    }
    let Some(imported) = imported else {
        return Err("FILE is required".into());
    };
    let csv = imported.to_csv();
    // Check the result reads back as a valid log before writing anything.
    uavgen::logs::parse_log(&csv, &out.display().to_string())
        .map_err(|e| format!("the imported log is invalid (a bug, please report it): {e}"))?;
    super::write_atomically(out, &csv)?;
    for w in imported.warnings() {
        eprintln!("warning: {w}");
    }
    println!("wrote {}: {}", out.display(), imported.report());
    Ok(())
}
