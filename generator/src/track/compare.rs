//! Fly two models on one plant and compare their tracking: `uavgen diagnose --plant` uses it to show
//! what the corrected model buys in closed loop.

use super::{build::build_harness, fly, HarnessBackend, StateExtender, TrackOptions, TrackReport};
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
    let samples = fly(
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
        &samples,
        &bounds,
    ))
}

/// Each of the paper's trajectories for `seconds`, base vs corrected, with the MPC options file `mpc`
/// (default: the paper's weights).
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
        });
    }
    Ok(runs)
}
