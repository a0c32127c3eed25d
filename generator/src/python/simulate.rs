//! `uavgen.simulate` (`uavgen simulate`) and `uavgen.track` (`uavgen track`).

use super::err;
use super::logs::PyLog;
use super::model::PyModel;
use crate::commands::track::{self as shared, Session};
use crate::sim::{PlantFile, SimulateOptions};
use crate::track::VerdictRules;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Fly profiles with a plant file; the log as CSV text read back by the log reader (its source is
/// `out` if given — the file is then written as `uavgen simulate --out` writes it — else `label`).
#[pyfunction]
#[pyo3(signature = (plant, profile = "excite", duration = "60", seed = 1, out = None, force = false, label = None))]
#[allow(clippy::too_many_arguments)]
fn simulate(
    py: Python<'_>,
    plant: PathBuf,
    profile: &str,
    duration: &str,
    seed: u64,
    out: Option<PathBuf>,
    force: bool,
    label: Option<String>,
) -> PyResult<PyLog> {
    if let Some(path) = out.as_ref().filter(|p| p.exists() && !force) {
        return Err(err(format!(
            "{}: exists; pass force=True to overwrite it",
            path.display()
        )));
    }
    let options = SimulateOptions::parse(profile, duration, seed).map_err(err)?;
    let plant_file = PlantFile::load(&plant).map_err(err)?;
    let text = py
        .allow_threads(|| crate::sim::simulate(&plant_file, &options).map(|log| log.to_csv()))
        .map_err(err)?;
    let source = match &out {
        Some(path) => {
            crate::sim::write_atomically(path, &text).map_err(err)?;
            path.display().to_string()
        }
        None => label.unwrap_or_else(|| format!("<simulated: {}>", plant.display())),
    };
    let log = crate::logs::parse_log(&text, &source).map_err(err)?;
    Ok(PyLog { log })
}

/// Closed-loop MPC on the plant simulator along the paper's trajectories: per trajectory the
/// report (the JSON of report.json), the samples (samples.csv's text) and the line the CLI prints.
/// `out` (a directory, one sub-directory per trajectory when several) receives the CLI's files.
#[pyfunction]
#[pyo3(signature = (model, plant, trajectories, duration = 30.0, seed = 1, horizon = 30, mpc_options_json = None, generic = false, max_rmse = crate::track::verdict::DEFAULT_MAX_RMSE, max_distance = crate::track::verdict::DEFAULT_MAX_DISTANCE, work_dir = PathBuf::from("target/uavgen-track"), out = None, force = false))]
#[allow(clippy::too_many_arguments)]
fn track(
    py: Python<'_>,
    model: PyRef<'_, PyModel>,
    plant: PathBuf,
    trajectories: Vec<String>,
    duration: f64,
    seed: u64,
    horizon: usize,
    mpc_options_json: Option<String>,
    generic: bool,
    max_rmse: f64,
    max_distance: f64,
    work_dir: PathBuf,
    out: Option<PathBuf>,
    force: bool,
) -> PyResult<Vec<(String, String, String)>> {
    if let Some(path) = out.as_ref().filter(|p| p.exists() && !force) {
        return Err(err(format!(
            "{}: exists; pass force=True to replace it",
            path.display()
        )));
    }
    let which: Vec<_> = trajectories
        .iter()
        .map(|n| shared::trajectory(n).map(|t| (n.clone(), t)))
        .collect::<Result<_, _>>()
        .map_err(err)?;
    if which.is_empty() {
        return Err(err("trajectories: at least one of circle, sinusoid, spiral"));
    }
    let rules = VerdictRules { max_rmse, max_distance };
    Session::check_duration(duration).map_err(err)?;
    rules.validate().map_err(err)?;
    Session::check_model(&model.model, &model.label).map_err(err)?;
    let plant_file = PlantFile::load(&plant).map_err(err)?;
    let mpc = match &mpc_options_json {
        Some(text) => Some(crate::MpcOptions::parse(&model.model, text, "mpc options").map_err(err)?),
        None => None,
    };
    let session = Session::new(
        model.model.clone(),
        &model.label,
        plant_file,
        &plant.display().to_string(),
        duration,
        seed,
        horizon,
        mpc,
        rules,
    )
    .map_err(err)?;
    py.allow_threads(|| -> Result<_, String> {
        let mut backend = if generic {
            session.generic_backend()?
        } else {
            session.harness_backend(&work_dir, |work| work())?
        };
        let several = which.len() > 1;
        let tmp = out.as_ref().map(|o| o.with_extension("uavgen-tmp"));
        if let Some(tmp) = &tmp {
            let _ = std::fs::remove_dir_all(tmp);
        }
        let mut results = Vec::new();
        let mut reports = Vec::new();
        let flown = (|| -> Result<(), String> {
            for (name, t) in &which {
                let (report, flight) = session.fly(backend.as_mut(), *t, name, &mut |_| {})?;
                if let Some(tmp) = &tmp {
                    let dir = if several { tmp.join(name) } else { tmp.clone() };
                    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
                    shared::write_flight(&dir, name, &report, &flight)?;
                }
                let json = serde_json::to_string_pretty(&report).map_err(|e| e.to_string())? + "\n";
                let samples = crate::track::report::samples_csv(&flight.samples);
                results.push((json, samples, shared::summary_line(name, &report)));
                reports.push(report);
            }
            if let (Some(tmp), true) = (&tmp, several) {
                let json = serde_json::to_string_pretty(&reports).map_err(|e| e.to_string())? + "\n";
                crate::sim::write_atomically(&tmp.join("summary.json"), &json).map_err(|e| e.to_string())?;
            }
            Ok(())
        })();
        if let (Some(tmp), Some(out)) = (&tmp, &out) {
            if let Err(e) = flown {
                let _ = std::fs::remove_dir_all(tmp);
                return Err(e);
            }
            if out.exists() {
                std::fs::remove_dir_all(out).map_err(|e| format!("{}: {e}", out.display()))?;
            }
            std::fs::rename(tmp, out).map_err(|e| format!("{}: {e}", out.display()))?;
        } else {
            flown?;
        }
        Ok(results)
    })
    .map_err(err)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(track, m)?)
}
