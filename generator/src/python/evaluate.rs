//! `uavgen.evaluate`: `uavgen evaluate`'s code path (crate::commands::evaluate).

use super::logs::PyLog;
use super::model::PyModel;
use super::{err, stale_policy};
use crate::evaluate::{evaluate as run, plot_states, EvaluateOptions};
use pyo3::prelude::*;
use std::path::PathBuf;

/// Evaluate `model` on `logs`: (the JSON `--json` writes, the text the CLI prints, the envelope
/// notes, the plot files written into `plots`).
#[pyfunction]
#[pyo3(signature = (model, logs, horizon = 30, substeps = None, stale = "interpolate", plots = None))]
fn evaluate(
    py: Python<'_>,
    model: PyRef<'_, PyModel>,
    logs: Vec<PyRef<'_, PyLog>>,
    horizon: usize,
    substeps: Option<usize>,
    stale: &str,
    plots: Option<PathBuf>,
) -> PyResult<(String, String, Vec<String>, Vec<String>)> {
    if let Some(dir) = plots.as_ref().filter(|d| d.exists() && !d.is_dir()) {
        return Err(err(format!("plots {}: exists and is not a directory", dir.display())));
    }
    let options = EvaluateOptions {
        horizon,
        substeps,
        stale: stale_policy(stale)?,
        ..EvaluateOptions::default()
    };
    crate::commands::evaluate::check_options(&options).map_err(err)?;
    if logs.is_empty() {
        return Err(err("logs: at least one flight log is needed"));
    }
    let model = &model.model;
    let logs: Vec<_> = logs.iter().map(|l| l.log.clone()).collect();
    let notes = crate::commands::evaluate::envelope_notes(model, &logs);
    let (evaluation, files) = py
        .allow_threads(|| -> Result<_, String> {
            let evaluation = run(model, &logs, &options).map_err(|e| e.to_string())?;
            let mut files = Vec::new();
            if let Some(dir) = &plots {
                let _guard = crate::interrupt::output_lock();
                std::fs::create_dir_all(dir).map_err(|e| format!("plots {}: {e}", dir.display()))?;
                for log in &logs {
                    let written = plot_states(model, log, &options, dir).map_err(|e| e.to_string())?;
                    files.extend(written.into_iter().map(|f| f.display().to_string()));
                }
            }
            Ok((evaluation, files))
        })
        .map_err(err)?;
    let json = serde_json::to_string_pretty(&evaluation).map_err(err)? + "\n";
    Ok((json, evaluation.to_string(), notes, files))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(evaluate, m)?)
}
