//! Fly two models on one plant and compare their tracking: `uavgen diagnose --plant` uses it to show
//! what the corrected model buys in closed loop.

use super::{build::build_harness, fly, HarnessBackend, StateExtender, TrackOptions, TrackReport, VerdictRules};
use crate::codegen::GenerateOptions;
use crate::diagnose::ClosedLoopRun;
use crate::sim::{Plant, PlantFile};
use crate::Model;
use std::path::Path;
use uavgen_runtime::Trajectory;

fn report(
    model: &Model,
    plant: &PlantFile,
    trajectory: Trajectory,
    seconds: f64,
    mpc: Option<&Path>,
    work: &Path,
) -> Result<TrackReport, String> {
    let dt = Plant::new(plant, 1).sample_period();
    let options = GenerateOptions {
        rate_hz: 1.0 / dt,
        mpc: match mpc {
            Some(p) => Some(crate::MpcOptions::load(model, p)?),
            None => None,
        },
        ..GenerateOptions::default()
    };
    let (name, binary) = build_harness(model, &options, work)?;
    let mut backend = HarnessBackend::spawn(&binary, &name)?;
    let mut extender = StateExtender::new(model, dt)?;
    let track = TrackOptions {
        trajectory,
        duration: seconds,
        ..TrackOptions::default()
    };
    let flight = fly(
        &mut backend,
        plant,
        &track,
        &mut |x, t, u| extender.extend(x, t, u),
        &mut |_, _| {},
    )?;
    let bounds = super::Backend::bounds(&backend);
    Ok(TrackReport::new(
        &model.name,
        &plant.name,
        "",
        &name,
        1,
        dt,
        &flight,
        &bounds,
        &VerdictRules::default(),
    ))
}

/// Each of the paper's trajectories for `seconds`, base vs corrected, with the MPC options file `mpc`
/// (default: `MpcOptions::defaults`).
pub fn compare(
    base: &Model,
    corrected: &Model,
    plant: &PlantFile,
    seconds: f64,
    mpc: Option<&Path>,
    work: &Path,
) -> Result<Vec<ClosedLoopRun>, String> {
    let mut runs = Vec::new();
    for (trajectory, name) in [
        (Trajectory::Sinusoidal, "sinusoid"),
        (Trajectory::Circular, "circle"),
        (Trajectory::Spiral, "spiral"),
    ] {
        let b = report(base, plant, trajectory, seconds, mpc, &work.join("base"))?;
        let a = report(corrected, plant, trajectory, seconds, mpc, &work.join("corrected"))?;
        runs.push(ClosedLoopRun {
            trajectory: name.into(),
            seconds,
            rmse_before: b.overall.rmse,
            rmse_after: a.overall.rmse,
            mae_before: b.overall.mae,
            mae_after: a.overall.mae,
            d1_before: b.overall.d1,
            d1_after: a.overall.d1,
            out_of_bounds_before: b.inputs_out_of_bounds,
            out_of_bounds_after: a.inputs_out_of_bounds,
            verdict_before: b.verdict,
            verdict_after: a.verdict,
        });
    }
    Ok(runs)
}

/// A run flies worse (better) with the corrected model when its `track` verdict is more (less)
/// severe, or, with the same verdict, its overall position RMSE is more than this fraction higher
/// (lower) than the base's.
pub const RMSE_CHANGE: f64 = 0.10;

/// How one run changed: +1 worse, −1 better, 0 neither.
fn change(r: &ClosedLoopRun) -> i32 {
    if r.verdict_after != r.verdict_before {
        return if r.verdict_after > r.verdict_before { 1 } else { -1 };
    }
    if r.rmse_after > (1.0 + RMSE_CHANGE) * r.rmse_before {
        1
    } else if r.rmse_after < (1.0 - RMSE_CHANGE) * r.rmse_before {
        -1
    } else {
        0
    }
}

fn describe(r: &ClosedLoopRun) -> String {
    let v = |b: crate::track::Verdict, a: crate::track::Verdict| {
        if a == b {
            String::new()
        } else {
            format!(", {b} → {a}")
        }
    };
    format!(
        "{} RMSE {:.3} → {:.3} m{}",
        r.trajectory,
        r.rmse_before,
        r.rmse_after,
        v(r.verdict_before, r.verdict_after)
    )
}

/// The comparison's verdict — `"worse"` when the corrected model flies worse than the base on any
/// trajectory (the corrections are then not recommended for closed loop, even if another
/// trajectory gains), `"better"` when it flies better on some and worse on none, else
/// `"no change"` — and the sentence that says so, then every run's numbers.
pub fn judge(runs: &[ClosedLoopRun], plant: &str) -> (String, String) {
    let worse: Vec<String> = runs.iter().filter(|r| change(r) > 0).map(describe).collect();
    let better: Vec<String> = runs.iter().filter(|r| change(r) < 0).map(describe).collect();
    let all = runs.iter().map(describe).collect::<Vec<_>>().join("; ");
    if !worse.is_empty() {
        let gains = if better.is_empty() {
            String::new()
        } else {
            format!(" (better on {})", better.join("; "))
        };
        (
            "worse".into(),
            format!(
                "NOT RECOMMENDED for closed loop: the corrected model flies worse than the base on {plant} ({}){gains}; fly the base model, or treat corrected.json as a finding to check, not as the fix. All runs: {all}",
                worse.join("; ")
            ),
        )
    } else if !better.is_empty() {
        (
            "better".into(),
            format!(
                "the corrected model flies better than the base on {plant} ({}). All runs: {all}",
                better.join("; ")
            ),
        )
    } else {
        (
            "no change".into(),
            format!(
                "the corrected model flies like the base on {plant} (no run changes its verdict or its RMSE by more than {:.0} %). All runs: {all}",
                100.0 * RMSE_CHANGE
            ),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::track::Verdict::{self, *};

    fn run(name: &str, before: (f64, Verdict), after: (f64, Verdict)) -> ClosedLoopRun {
        ClosedLoopRun {
            trajectory: name.into(),
            seconds: 30.0,
            rmse_before: before.0,
            rmse_after: after.0,
            mae_before: 0.0,
            mae_after: 0.0,
            d1_before: 0.0,
            d1_after: 0.0,
            out_of_bounds_before: 0,
            out_of_bounds_after: 0,
            verdict_before: before.1,
            verdict_after: after.1,
        }
    }

    #[test]
    fn a_corrected_model_that_flies_worse_is_not_recommended() {
        // issue 13: the circle 5.18 → 7.16 m on m100_like, the other two unchanged.
        let runs = [
            run("sinusoid", (0.25, Tracked), (0.25, Tracked)),
            run("circle", (5.18, DidNotTrack), (7.16, DidNotTrack)),
            run("spiral", (0.30, Tracked), (0.29, Tracked)),
        ];
        let (v, note) = judge(&runs, "m100_like.json");
        assert_eq!(v, "worse");
        assert!(note.starts_with("NOT RECOMMENDED"), "{note}");
        assert!(note.contains("circle RMSE 5.180 → 7.160 m"), "{note}");
        // Better elsewhere does not make it the fix.
        let runs = [
            run("sinusoid", (3.0, DidNotTrack), (0.2, Tracked)),
            run("circle", (0.25, Tracked), (0.4, DidNotTrack)),
        ];
        let (v, note) = judge(&runs, "p");
        assert_eq!(v, "worse");
        assert!(
            note.contains("tracked → did not track") && note.contains("better on sinusoid"),
            "{note}"
        );
        // A verdict that worsens counts even when the RMSE of a shorter, lost flight is lower.
        let (v, _) = judge(&[run("circle", (5.0, DidNotTrack), (4.0, Diverged))], "p");
        assert_eq!(v, "worse");
    }

    #[test]
    fn better_and_no_change() {
        let (v, note) = judge(
            &[
                run("sinusoid", (0.25, Tracked), (0.26, Tracked)),
                run("circle", (5.5, DidNotTrack), (0.24, Tracked)),
            ],
            "p",
        );
        assert_eq!(v, "better");
        assert!(
            note.contains("circle RMSE 5.500 → 0.240 m, did not track → tracked"),
            "{note}"
        );
        let (v, _) = judge(&[run("circle", (0.25, Tracked), (0.27, Tracked))], "p");
        assert_eq!(v, "no change");
        let (v, _) = judge(&[run("circle", (0.25, Tracked), (0.28, Tracked))], "p");
        assert_eq!(v, "worse");
    }
}
