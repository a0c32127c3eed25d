//! `uavgen simulate`: fly profiles with a plant file and write a flight log (docs/simulate.md).

use clap::Args;
use std::path::PathBuf;
use uavgen::sim::{simulate, PlantFile, SimulateOptions};

#[derive(Args)]
pub struct SimulateArgs {
    /// Plant file (uavgen-plant/1 JSON, docs/plant-format.md).
    #[arg(long)]
    plant: PathBuf,
    /// Profile, or a comma list (one segment each): excite, excite-hold-heading, hover, circle,
    /// sinusoid, spiral.
    #[arg(long, default_value = "excite")]
    profile: String,
    /// Seconds per segment, a comma list as long as --profile.
    #[arg(long, default_value = "60")]
    duration: String,
    /// Seed of every random process (excitation, noise, stale samples, turbulence).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output log (docs/log-format.md CSV).
    #[arg(long)]
    out: PathBuf,
    /// Overwrite --out if it exists.
    #[arg(long)]
    force: bool,
}

pub fn run(args: SimulateArgs) -> Result<(), String> {
    super::refuse_existing(&args.out, args.force)?;
    let options = SimulateOptions::parse(&args.profile, &args.duration, args.seed).map_err(|e| e.to_string())?;
    let plant = PlantFile::load(&args.plant).map_err(|e| e.to_string())?;
    let log = super::progress::with_spinner("simulating", || simulate(&plant, &options)).map_err(|e| e.to_string())?;
    super::progress::with_spinner("writing the log", || log.write(&args.out)).map_err(|e| e.to_string())?;
    let effects = plant.effects.active();
    println!(
        "wrote {}: {} rows in {} segment{} at {} Hz, plant `{}` ({}), seed {}",
        args.out.display(),
        log.rows.len(),
        log.segments.len(),
        if log.segments.len() == 1 { "" } else { "s" },
        log.rate_hz,
        plant.name,
        if effects.is_empty() {
            "no effects".to_owned()
        } else {
            effects.join(", ")
        },
        args.seed
    );
    for s in &log.segments {
        println!(
            "  segment {} {:<8} t {:.1}..{:.1} s: z {:.2}..{:.2} m, max |x|,|y| {:.2} m, tilt ≤ {:.3} rad, speed ≤ {:.2} m/s, \
             thrust saturated {:.2} %, {} stale rows, battery {:.2} V",
            s.segment,
            s.profile,
            s.t_start,
            s.t_start + s.duration_s,
            s.min_z,
            s.max_z,
            s.max_abs_xy,
            s.max_tilt_rad,
            s.max_speed,
            100.0 * s.thrust_saturation_fraction,
            s.held_rows,
            s.battery_voltage_end
        );
    }
    Ok(())
}
