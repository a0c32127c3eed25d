//! `uavgen.diagnose`: `uavgen diagnose`'s code path (crate::commands::diagnose).

use super::logs::PyLog;
use super::model::PyModel;
use super::{err, stale_policy};
use crate::diagnose::{diagnose_with_progress, DiagnoseOptions, ResidualKind};
use crate::identify::preprocess::SavGol;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Diagnose `model` on `logs` (scored on `holdout`, else cross-validation): (report.json's text,
/// corrected.json's text, the warnings, the files written into `out` if given).
#[pyfunction]
#[pyo3(signature = (model, logs, holdout = Vec::new(), out = None, force = false, horizon = 30, substeps = None, rotor_radius = 0.1651, gravity = None, effects = None, max_effects = 3, max_delta_bic = crate::diagnose::Rules::default().max_delta_bic, min_reduction = crate::diagnose::Rules::default().min_reduction, min_z = crate::diagnose::Rules::default().min_z, savgol_window = 9, savgol_order = 3, plant = None, mpc = None, pointwise = false, where_analysis = true, stale = "interpolate"))]
#[allow(clippy::too_many_arguments)]
fn diagnose(
    py: Python<'_>,
    model: PyRef<'_, PyModel>,
    logs: Vec<PyRef<'_, PyLog>>,
    holdout: Vec<PyRef<'_, PyLog>>,
    out: Option<PathBuf>,
    force: bool,
    horizon: usize,
    substeps: Option<usize>,
    rotor_radius: f64,
    gravity: Option<f64>,
    effects: Option<Vec<String>>,
    max_effects: usize,
    max_delta_bic: f64,
    min_reduction: f64,
    min_z: f64,
    savgol_window: usize,
    savgol_order: usize,
    plant: Option<PathBuf>,
    mpc: Option<PathBuf>,
    pointwise: bool,
    where_analysis: bool,
    stale: &str,
) -> PyResult<(String, String, Vec<String>, Vec<String>)> {
    if logs.is_empty() {
        return Err(err("logs: at least one training log is needed"));
    }
    if let Some(path) = out.as_ref().filter(|p| p.exists() && !force) {
        return Err(err(format!(
            "{}: exists; pass force=True to replace it",
            path.display()
        )));
    }
    let savgol =
        SavGol::new(savgol_window, savgol_order).map_err(|e| err(format!("--savgol-window/--savgol-order: {e}")))?;
    let candidates = crate::commands::diagnose::effects(effects.as_deref()).map_err(err)?;
    let rules = crate::commands::diagnose::rules(max_effects, max_delta_bic, min_reduction, min_z).map_err(err)?;
    let train: Vec<_> = logs.iter().map(|l| l.log.clone()).collect();
    let held: Vec<_> = holdout.iter().map(|l| l.log.clone()).collect();
    let names = |v: &[crate::logs::FlightLog]| v.iter().map(|l| l.source.clone()).collect::<Vec<_>>();
    let options = DiagnoseOptions {
        savgol,
        residual: if pointwise {
            ResidualKind::Pointwise
        } else {
            ResidualKind::Matched
        },
        horizon,
        substeps,
        gravity,
        rotor_radius,
        rules,
        candidates,
        where_analysis,
        stale: stale_policy(stale)?,
        model_text: Some(model.text.clone()),
        source: Some(crate::commands::diagnose::source(
            &model.label,
            &names(&train),
            &names(&held),
        )),
        plant: plant.clone(),
        ..DiagnoseOptions::default()
    };
    let base = &model.model;
    py.allow_threads(|| -> Result<_, String> {
        let mut d = diagnose_with_progress(base, &train, &held, &options, &mut |_| {}).map_err(|e| e.to_string())?;
        if let Some(plant) = &plant {
            d.shrink.closed_loop =
                crate::commands::diagnose::closed_loop(base, &d.corrected, plant, mpc.as_deref(), |work| work());
        }
        let files = match &out {
            Some(dir) => d
                .write(dir, force)
                .map_err(|e| e.to_string())?
                .iter()
                .map(|f| f.display().to_string())
                .collect(),
            None => Vec::new(),
        };
        let corrected = serde_json::to_string_pretty(&d.corrected).map_err(|e| e.to_string())? + "\n";
        Ok((d.report_json(), corrected, d.warnings.clone(), files))
    })
    .map_err(err)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(diagnose, m)?)
}
