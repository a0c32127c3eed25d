//! `uavgen diagnose`: where a model parts from flight data, which catalogued effect explains it,
//! how far adding it shrinks the gap, and the corrected model (docs/diagnose.md).

use clap::Args;
use std::path::PathBuf;
use uavgen::diagnose::{diagnose_with_progress, DiagnoseOptions, ResidualKind, Rules};
use uavgen::identify::preprocess::SavGol;

#[derive(Args)]
pub struct DiagnoseArgs {
    /// Model file (uavgen-model/1, without a `corrections` block).
    #[arg(long, required_unless_present = "self_check")]
    model: Option<PathBuf>,
    /// Training flight log (docs/log-format.md CSV); repeat for several.
    #[arg(long = "log", required_unless_present = "self_check")]
    logs: Vec<PathBuf>,
    /// Held-out flight log the candidates are scored on; repeat for several. Without one:
    /// cross-validation over the training logs.
    #[arg(long = "holdout")]
    holdout: Vec<PathBuf>,
    /// How to read --log / --holdout files that are not CSV (PX4 ULog, …): a preset (px4, mavros,
    /// dji-osdk-ros, ardupilot) or a profile file (docs/import.md).
    #[arg(long)]
    profile: Option<String>,
    /// Output directory: report.md, report.json, corrected.json and the plots.
    #[arg(long)]
    out: PathBuf,
    /// Replace --out if it exists.
    #[arg(long)]
    force: bool,
    /// Free-run horizon in samples (the MPC's).
    #[arg(long, default_value_t = 30)]
    horizon: usize,
    /// RK4 substeps per sample (default: the automatic rule).
    #[arg(long)]
    substeps: Option<usize>,
    /// Rotor radius of the ground effect, m.
    #[arg(long, default_value_t = 0.1651)]
    rotor_radius: f64,
    /// g of the thrust effects, m/s² (default: the PD model's, else 9.81).
    #[arg(long)]
    gravity: Option<f64>,
    /// Only these candidate effects (comma separated; default: the whole catalogue).
    #[arg(long, value_delimiter = ',')]
    effects: Option<Vec<String>>,
    /// Name at most this many effects.
    #[arg(long, default_value_t = 3)]
    max_effects: usize,
    /// Selection rule: the held-out ΔBIC must be below this.
    #[arg(long, default_value_t = Rules::default().max_delta_bic, allow_hyphen_values = true)]
    max_delta_bic: f64,
    /// Selection rule: the held-out RMSE reduction of the affected channels must reach this fraction.
    #[arg(long, default_value_t = Rules::default().min_reduction)]
    min_reduction: f64,
    /// Selection rule: the training z of the parameter must exceed this.
    #[arg(long, default_value_t = Rules::default().min_z)]
    min_z: f64,
    /// Savitzky-Golay window (odd) of the derivative targets.
    #[arg(long, default_value_t = 9)]
    savgol_window: usize,
    /// Savitzky-Golay polynomial order.
    #[arg(long, default_value_t = 3)]
    savgol_order: usize,
    /// Plant file for a closed-loop comparison through `uavgen track`: the base and the corrected
    /// model fly the paper's three trajectories (30 s each); a corrected model that flies worse is
    /// flagged "not recommended for closed loop".
    #[arg(long)]
    plant: Option<PathBuf>,
    /// MPC options file of the closed-loop comparison (docs/mpc.md; default: the paper's weights but
    /// q = 1 on yaw, r = 10 on u_yaw_rate and r_delta = 50 on u_roll and u_pitch, as every command).
    #[arg(long, requires = "plant")]
    mpc: Option<PathBuf>,
    /// Compare the model with the derivative pointwise (ẋ_SG − f(x, u), the identification's target)
    /// instead of through the derivative's own filter.
    #[arg(long)]
    pointwise: bool,
    /// Skip the "where" residual analysis (and its plots).
    #[arg(long)]
    no_where: bool,
    /// Stale rows (a row whose 12 states repeat the previous row's): `interpolate` treats them as
    /// missing samples from the start, so every figure is the one `uavgen evaluate` (same default)
    /// gives on the same log; `keep` uses the logs as recorded.
    #[arg(long, value_enum, default_value_t = uavgen::logs::StalePolicy::Interpolate)]
    stale: uavgen::logs::StalePolicy,
    /// Run the protocol on withheld effects instead (docs/diagnosis.md): the simulator flies nominal
    /// logs and logs with each plant effect; a model identified from the nominal ones is diagnosed
    /// against each. Prints the results and writes selfcheck.md and selfcheck.json into --out.
    #[arg(long, conflicts_with_all = ["model", "logs", "holdout"])]
    self_check: bool,
    /// Self-check: only every effect at realistic magnitude, one pair and nominal logs (what CI runs).
    #[arg(long, requires = "self_check")]
    reduced: bool,
    /// Self-check: the directory with nominal.json and effects/*.json.
    #[arg(long, default_value = "plants", requires = "self_check")]
    plants: PathBuf,
    /// Self-check: also put the results into this Markdown file, between the lines
    /// `<!-- self-check:begin -->` and `<!-- self-check:end -->` (e.g. docs/diagnosis.md).
    #[arg(long, requires = "self_check")]
    write_doc: Option<PathBuf>,
}

fn self_check(args: &DiagnoseArgs) -> Result<(), String> {
    use uavgen::selfcheck::{self, cases, SelfCheckOptions};
    let options = SelfCheckOptions {
        cases: if args.reduced {
            cases::reduced_cases()
        } else {
            cases::default_cases()
        },
        ..SelfCheckOptions::default()
    };
    super::refuse_existing(&args.out, args.force)?;
    let bar = super::progress::bar(options.cases.len(), "cases");
    let check = selfcheck::run(&args.plants, &options, &mut |done, _, case| {
        bar.set_position(done as u64);
        bar.set_message(case.to_string());
    })?;
    bar.finish_and_clear();
    let md = check.markdown();
    println!("{md}");
    // One critical section: an interrupting signal waits for it (uavgen::interrupt).
    let guard = uavgen::interrupt::output_lock();
    let tmp = args.out.with_extension("uavgen-tmp");
    let _ = std::fs::remove_dir_all(&tmp);
    std::fs::create_dir_all(&tmp).map_err(|e| format!("{}: {e}", tmp.display()))?;
    let json = serde_json::to_string_pretty(&check).map_err(|e| e.to_string())? + "\n";
    std::fs::write(tmp.join("selfcheck.json"), json).map_err(|e| e.to_string())?;
    std::fs::write(tmp.join("selfcheck.md"), &md).map_err(|e| e.to_string())?;
    if args.out.exists() {
        std::fs::remove_dir_all(&args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    }
    std::fs::rename(&tmp, &args.out).map_err(|e| format!("{}: {e}", args.out.display()))?;
    drop(guard);
    if let Some(doc) = &args.write_doc {
        let text = std::fs::read_to_string(doc).map_err(|e| format!("{}: {e}", doc.display()))?;
        let (begin, end) = ("<!-- self-check:begin -->", "<!-- self-check:end -->");
        let (Some(a), Some(b)) = (text.find(begin), text.find(end)) else {
            return Err(format!("{}: no `{begin}` … `{end}` section to replace", doc.display()));
        };
        if b < a {
            return Err(format!("{}: `{end}` comes before `{begin}`", doc.display()));
        }
        let new = format!("{}{begin}\n{md}{}", &text[..a], &text[b..]);
        super::write_atomically(doc, &new)?;
    }
    println!(
        "self-check: {} of {} cases pass; wrote {}",
        check.results.iter().filter(|r| r.passes()).count(),
        check.results.len(),
        args.out.display()
    );
    if check.passed() {
        Ok(())
    } else {
        Err("self-check: some cases fail (see the table)".into())
    }
}

/// The base and the corrected model flown on `plant` along the paper's trajectories (30 s each).
fn closed_loop(
    base: &uavgen::Model,
    corrected: &serde_json::Value,
    plant: &std::path::Path,
    mpc: Option<&std::path::Path>,
) -> uavgen::diagnose::ClosedLoop {
    uavgen::commands::diagnose::closed_loop(base, corrected, plant, mpc, |work| {
        eprintln!("flying the base and the corrected model on {} ...", plant.display());
        super::progress::with_spinner("closed loops: base and corrected model", work)
    })
}

fn read_logs(paths: &[PathBuf], profile: Option<&str>) -> Result<Vec<uavgen::logs::FlightLog>, String> {
    let mut logs = Vec::new();
    for path in paths {
        let log = uavgen::logs::load_any(path, profile).map_err(|e| e.to_string())?;
        for w in log.report.warnings() {
            eprintln!("warning: {}: {w}", path.display());
        }
        logs.push(log);
    }
    Ok(logs)
}

pub fn run(args: DiagnoseArgs) -> Result<(), String> {
    if args.self_check {
        return self_check(&args);
    }
    let (Some(model_path), false) = (args.model.clone(), args.logs.is_empty()) else {
        return Err("--model and --log are required (or --self-check)".into());
    };
    super::refuse_existing(&args.out, args.force)?;
    let savgol = SavGol::new(args.savgol_window, args.savgol_order)
        .map_err(|e| format!("--savgol-window/--savgol-order: {e}"))?;
    let candidates = uavgen::commands::diagnose::effects(args.effects.as_deref())?;
    let rules =
        uavgen::commands::diagnose::rules(args.max_effects, args.max_delta_bic, args.min_reduction, args.min_z)?;
    let model = uavgen::load(&model_path).map_err(|e| e.to_string())?;
    let text = std::fs::read_to_string(&model_path).map_err(|e| format!("{}: {e}", model_path.display()))?;
    let train = read_logs(&args.logs, args.profile.as_deref())?;
    let holdout = read_logs(&args.holdout, args.profile.as_deref())?;
    let options = DiagnoseOptions {
        savgol,
        residual: if args.pointwise {
            ResidualKind::Pointwise
        } else {
            ResidualKind::Matched
        },
        horizon: args.horizon,
        substeps: args.substeps,
        gravity: args.gravity,
        rotor_radius: args.rotor_radius,
        rules,
        candidates,
        where_analysis: !args.no_where,
        stale: args.stale,
        model_text: Some(text),
        source: Some(uavgen::commands::diagnose::source(
            &model_path.display().to_string(),
            &args.logs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
            &args.holdout.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        )),
        plant: args.plant.clone(),
        ..DiagnoseOptions::default()
    };
    eprintln!(
        "diagnosing {} on {} training log(s), {} ...",
        model.name,
        train.len(),
        if holdout.is_empty() {
            "cross-validation".to_string()
        } else {
            format!("{} held-out log(s)", holdout.len())
        }
    );
    let bar = super::progress::bar(0, "candidates");
    let mut d = diagnose_with_progress(&model, &train, &holdout, &options, &mut |p| {
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        bar.set_message(p.what.to_string());
    })
    .map_err(|e| e.to_string())?;
    bar.finish_and_clear();
    for w in &d.warnings {
        eprintln!("warning: {w}");
    }
    println!("verdict: {}", d.verdict.join(" + "));
    for e in d.effects.iter().take(4) {
        println!(
            "  {:<15} held-out ΔBIC {:>9.1}, RMSE reduction {:>5.1} %, z {:>6.1}{}",
            e.name,
            e.score,
            100.0 * e.heldout_reduction,
            e.z,
            if e.selected { "  (named)" } else { "" }
        );
    }
    if d.verdict.iter().any(|v| v != "none" && v != "stale_samples") {
        println!("command channels, step response of the corrected model against the base model:");
        for t in &d.response_times {
            println!("  {}", t.sentence());
        }
    }
    if let (Some(b), Some(a)) = (&d.shrink.before.horizon, &d.shrink.after.horizon) {
        println!(
            "held-out horizon RMSE (overall, {} samples): {:.4} → {:.4}",
            d.shrink.horizon, b.overall_rmse, a.overall_rmse
        );
    }
    if let Some(plant) = &args.plant {
        d.shrink.closed_loop = closed_loop(&model, &d.corrected, plant, args.mpc.as_deref());
        println!("closed loop on {}: {}", plant.display(), d.shrink.closed_loop.note);
        if d.shrink.closed_loop.verdict.as_deref() == Some("worse") {
            println!(
                "verdict for closed loop: the corrections are NOT recommended — the corrected model flies worse than the base on {}",
                plant.display()
            );
        }
    }
    let files = d.write(&args.out, args.force).map_err(|e| e.to_string())?;
    println!("wrote {} files into {}", files.len(), args.out.display());
    Ok(())
}
