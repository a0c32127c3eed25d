//! `uavgen diagnose` (and `uavgen.diagnose` in Python): the option checks, the provenance of the
//! corrections and the closed-loop comparison, shared by both front ends.

use crate::diagnose::{ClosedLoop, ClosedLoopRun, EffectKind, Rules};
use crate::model::Model;
use std::path::Path;

/// The candidate effects by name (`None`: the whole catalogue), with the CLI's message.
pub fn effects(names: Option<&[String]>) -> Result<Vec<EffectKind>, String> {
    match names {
        None => Ok(EffectKind::ALL.to_vec()),
        Some(names) => names
            .iter()
            .map(|n| {
                EffectKind::from_name(n.trim()).ok_or_else(|| {
                    let all: Vec<&str> = EffectKind::ALL.iter().map(|e| e.name()).collect();
                    format!("--effects: unknown effect `{n}` (the catalogue: {})", all.join(", "))
                })
            })
            .collect(),
    }
}

/// The selection rules, checked with the CLI's messages.
pub fn rules(max_effects: usize, max_delta_bic: f64, min_reduction: f64, min_z: f64) -> Result<Rules, String> {
    if max_effects == 0 {
        return Err("--max-effects: must be at least 1".into());
    }
    for (name, v) in [
        ("max-delta-bic", max_delta_bic),
        ("min-reduction", min_reduction),
        ("min-z", min_z),
    ] {
        if !v.is_finite() {
            return Err(format!("--{name}: must be a finite number, got {v}"));
        }
    }
    Ok(Rules {
        max_effects,
        max_delta_bic,
        min_reduction,
        min_z,
    })
}

/// The `source` of the corrections block: the command line that made them.
pub fn source(model: &str, logs: &[String], holdout: &[String]) -> String {
    format!(
        "uavgen {} diagnose --model {model} {}{}",
        env!("CARGO_PKG_VERSION"),
        logs.iter().map(|p| format!("--log {p}")).collect::<Vec<_>>().join(" "),
        holdout.iter().map(|p| format!(" --holdout {p}")).collect::<String>()
    )
}

/// The base and the corrected model flown on `plant` along the paper's trajectories (30 s each),
/// through `uavgen track`'s generated crate (built in target/uavgen-track/diagnose). `run` runs
/// the flights once the files are read (the CLI announces them and shows a spinner).
pub fn closed_loop(
    base: &Model,
    corrected: &serde_json::Value,
    plant: &Path,
    mpc: Option<&Path>,
    run: impl FnOnce(&dyn Fn() -> Result<Vec<ClosedLoopRun>, String>) -> Result<Vec<ClosedLoopRun>, String>,
) -> ClosedLoop {
    let flights = || -> Result<Vec<ClosedLoopRun>, String> {
        let plant_file = crate::PlantFile::load(plant).map_err(|e| e.to_string())?;
        let text = serde_json::to_string(corrected).map_err(|e| e.to_string())?;
        let corrected = crate::model::parse(&text, "corrected.json").map_err(|e| e.to_string())?;
        run(&|| {
            crate::track::compare::compare(
                base,
                &corrected,
                &plant_file,
                30.0,
                mpc,
                Path::new("target/uavgen-track/diagnose"),
            )
        })
    };
    match flights() {
        Ok(runs) => {
            let (verdict, note) = crate::track::compare::judge(&runs, &plant.display().to_string());
            ClosedLoop {
                status: "measured".into(),
                plant: Some(plant.display().to_string()),
                note,
                verdict: Some(verdict),
                runs,
            }
        }
        Err(e) => ClosedLoop {
            status: "failed".into(),
            plant: Some(plant.display().to_string()),
            note: e,
            verdict: None,
            runs: Vec::new(),
        },
    }
}
