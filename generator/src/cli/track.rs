//! `uavgen track`: closed-loop MPC on the plant simulator (docs/track.md).

use clap::{Args, ValueEnum};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Exit status when a loop did not track (none diverged); docs/track.md.
pub const EXIT_DID_NOT_TRACK: u8 = 3;
/// Exit status when a loop diverged.
pub const EXIT_DIVERGED: u8 = 4;
use uavgen::commands::track::Session;
use uavgen::sim::PlantFile;
use uavgen::track::{self, Backend, TrackReport, Verdict, VerdictRules};
use uavgen_runtime::Trajectory;

#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug)]
pub enum TrajectoryArg {
    /// x = 5 cos t, y = 5 sin t, z = 6.
    Circle,
    /// x = 4 sin(0.32 t) + 3, y = 4 sin(0.64 t), z = 2 sin(0.64 t) + 6.
    Sinusoid,
    /// x = e^{0.06 t} cos t, y = e^{0.06 t} sin t, z = 0.1 t + 5.
    Spiral,
}

impl TrajectoryArg {
    fn trajectory(self) -> Trajectory {
        match self {
            TrajectoryArg::Circle => Trajectory::Circular,
            TrajectoryArg::Sinusoid => Trajectory::Sinusoidal,
            TrajectoryArg::Spiral => Trajectory::Spiral,
        }
    }

    fn name(self) -> &'static str {
        match self {
            TrajectoryArg::Circle => "circle",
            TrajectoryArg::Sinusoid => "sinusoid",
            TrajectoryArg::Spiral => "spiral",
        }
    }
}

#[derive(Args)]
#[command(
    after_help = "Verdict per trajectory (docs/track.md): `tracked` (overall position RMSE ≤ --max-rmse), \
`did not track` (above it), `diverged` (the flight was lost: the true state not finite, the true position farther \
than --max-distance from the reference, or the aircraft on the ground; the flight stops there). \
Exit status: 0 every trajectory tracked; 3 some did not track (none diverged); 4 some diverged \
(the reports are written in all three cases); 1 an error (nothing written); 2 a usage error. \
Pass --max-rmse inf to fail on divergence only."
)]
pub struct TrackArgs {
    /// Model file (uavgen-model/1) the MPC uses.
    #[arg(long)]
    model: PathBuf,
    /// Plant file (docs/plant-format.md) the MPC controls.
    #[arg(long)]
    plant: PathBuf,
    /// Trajectory (comma separated for several: one sub-directory each).
    #[arg(long, value_enum, value_delimiter = ',', required = true)]
    trajectory: Vec<TrajectoryArg>,
    /// Output directory (report.md, report.json, samples.csv, path_3d.svg, position_errors.svg).
    #[arg(long)]
    out: PathBuf,
    /// Replace --out if it exists.
    #[arg(long)]
    force: bool,
    /// Use the generic reference solver (interpreted model + clarabel) instead of the generated crate.
    #[arg(long)]
    generic: bool,
    /// Flight time in s.
    #[arg(long, default_value_t = 30.0)]
    duration: f64,
    /// The plant's random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// MPC horizon N.
    #[arg(long, default_value_t = 30)]
    horizon: usize,
    /// MPC options file (weights, bounds; docs/mpc.md). Default: the paper's weights and bounds but
    /// q = 1 on yaw, r = 10 on u_yaw_rate and an input-rate weight r_delta = 50 on u_roll and u_pitch; examples/mpc_paper.json has the paper's own.
    #[arg(long)]
    mpc: Option<PathBuf>,
    /// Largest overall position RMSE (m, whole flight, approach included) of a loop that tracked;
    /// above it the verdict is `did not track` (exit status 3). The default suits 30 s flights; the
    /// approach weighs more in shorter ones (about 0.30·√(30/duration)). `inf`: judge divergence only.
    #[arg(long, default_value_t = track::verdict::DEFAULT_MAX_RMSE)]
    max_rmse: f64,
    /// A true position farther than this (m) from the reference is a lost flight: verdict
    /// `diverged` (exit status 4), the flight stops there.
    #[arg(long, default_value_t = track::verdict::DEFAULT_MAX_DISTANCE)]
    max_distance: f64,
    /// Scratch directory for the generated crate and the harness build.
    #[arg(long, default_value = "target/uavgen-track")]
    work_dir: PathBuf,
}

/// Runs `uavgen track`; Ok carries the exit status of the verdicts (0, 3 or 4).
pub fn run(args: TrackArgs) -> Result<ExitCode, String> {
    super::refuse_existing(&args.out, args.force)?;
    let rules = VerdictRules {
        max_rmse: args.max_rmse,
        max_distance: args.max_distance,
    };
    // The duration and the rules are checked before the files are read (as ever).
    Session::check_duration(args.duration)?;
    rules.validate()?;
    let model = uavgen::load(&args.model).map_err(|e| e.to_string())?;
    Session::check_model(&model, &args.model.display().to_string())?;
    let plant = PlantFile::load(&args.plant).map_err(|e| e.to_string())?;
    let mpc = match &args.mpc {
        Some(p) => Some(uavgen::MpcOptions::load(&model, p)?),
        None => None,
    };
    let session = Session::new(
        model,
        &args.model.display().to_string(),
        plant,
        &args.plant.display().to_string(),
        args.duration,
        args.seed,
        args.horizon,
        mpc,
        rules,
    )?;

    let mut backend: Box<dyn Backend> = if args.generic {
        session.generic_backend()?
    } else {
        eprintln!("building the generated solver and the tracking harness ...");
        session.harness_backend(&args.work_dir, |work| super::progress::with_spinner("building", work))?
    };

    // Everything goes to a scratch directory first, renamed into place at the end.
    let tmp = args.out.with_extension("uavgen-tmp");
    let _ = std::fs::remove_dir_all(&tmp);
    let reports = match fly_all(&args, &session, backend.as_mut(), &tmp) {
        Ok(r) => r,
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(e);
        }
    };
    if args.out.exists() {
        std::fs::remove_dir_all(&args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    }
    std::fs::rename(&tmp, &args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    println!("wrote {}", args.out.display());
    let count = |v: Verdict| reports.iter().filter(|r| r.verdict == v).count();
    let (tracked, untracked, diverged) = (
        count(Verdict::Tracked),
        count(Verdict::DidNotTrack),
        count(Verdict::Diverged),
    );
    let failed: Vec<String> = reports
        .iter()
        .filter(|r| r.verdict != Verdict::Tracked)
        .map(|r| format!("{} {}", r.trajectory, r.verdict))
        .collect();
    println!(
        "verdict: {tracked} of {} tracked{}",
        reports.len(),
        if failed.is_empty() {
            String::new()
        } else {
            format!(" ({})", failed.join(", "))
        }
    );
    Ok(if diverged > 0 {
        eprintln!("error: {diverged} loop(s) diverged (exit status {EXIT_DIVERGED})");
        ExitCode::from(EXIT_DIVERGED)
    } else if untracked > 0 {
        eprintln!(
            "error: {untracked} loop(s) did not track within --max-rmse {} m (exit status {EXIT_DID_NOT_TRACK})",
            rules.max_rmse
        );
        ExitCode::from(EXIT_DID_NOT_TRACK)
    } else {
        ExitCode::SUCCESS
    })
}

fn fly_all(
    args: &TrackArgs,
    session: &Session,
    backend: &mut dyn Backend,
    tmp: &Path,
) -> Result<Vec<TrackReport>, String> {
    let several = args.trajectory.len() > 1;
    let mut summary = Vec::new();
    for &which in &args.trajectory {
        let dir = if several {
            tmp.join(which.name())
        } else {
            tmp.to_path_buf()
        };
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let bar = super::progress::bar(session.planned_samples(), which.name());
        let (report, flight) = session.fly(backend, which.trajectory(), which.name(), &mut |done| {
            bar.set_position(done as u64)
        })?;
        bar.finish_and_clear();
        uavgen::commands::track::write_flight(&dir, which.name(), &report, &flight)?;
        println!("{}", uavgen::commands::track::summary_line(which.name(), &report));
        if let Some(w) = report.chatter_warning() {
            println!("{}: warning: {w}", which.name());
        }
        summary.push(report);
    }
    if several {
        let json = serde_json::to_string_pretty(&summary).map_err(|e| e.to_string())? + "\n";
        super::write_atomically(&tmp.join("summary.json"), &json)?;
    }
    Ok(summary)
}
