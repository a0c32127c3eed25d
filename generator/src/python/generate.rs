//! `uavgen.generate`: `uavgen --model … --horizon …`'s code path (crate::commands::generate).

use super::err;
use super::model::PyModel;
use crate::codegen::{Float, GenerateOptions, QpChoice};
use pyo3::prelude::*;
use std::path::PathBuf;

/// Generate the crate of the model given as JSON text into `out` (what `uavgen --model` does);
/// `out` None: `./<crate name>`, as the CLI; `mpc_options_json` is the text of an MPC options file (docs/mpc.md). Returns the crate name,
/// the directory written, the substeps per sample and the lines the CLI prints.
#[pyfunction]
#[pyo3(signature = (model_json, horizon, out, c_api, mpc_options_json, force, rate_hz = 30.0, substeps = None, float = "f64", qp = "auto", crate_name = None, model_label = "<model>"))]
#[allow(clippy::too_many_arguments)]
fn generate(
    py: Python<'_>,
    model_json: String,
    horizon: usize,
    out: Option<PathBuf>,
    c_api: bool,
    mpc_options_json: Option<String>,
    force: bool,
    rate_hz: f64,
    substeps: Option<usize>,
    float: &str,
    qp: &str,
    crate_name: Option<String>,
    model_label: &str,
) -> PyResult<(String, String, usize, Vec<String>)> {
    let m = PyModel::parse(model_json, model_label)?;
    let model = &m.model;
    let mpc = match &mpc_options_json {
        Some(text) => Some(crate::MpcOptions::parse(model, text, "mpc options").map_err(err)?),
        None => None,
    };
    let options = GenerateOptions {
        mpc,
        horizon,
        rate_hz,
        substeps,
        float: match float {
            "f64" => Float::F64,
            "f32" => Float::F32,
            other => return Err(err(format!("float: `{other}` is not one of f64, f32"))),
        },
        crate_name,
        c_api,
        qp: match qp {
            "auto" => QpChoice::Auto,
            "condensed" => QpChoice::Condensed,
            "riccati" => QpChoice::Riccati,
            other => return Err(err(format!("qp: `{other}` is not one of auto, condensed, riccati"))),
        },
        ..GenerateOptions::default()
    };
    let written = py
        .allow_threads(|| {
            crate::commands::generate::generate_into(model, model_label, &options, out.as_deref(), force, |work| work())
        })
        .map_err(err)?;
    Ok((
        written.generated.crate_name.clone(),
        written.out.display().to_string(),
        written.generated.substeps,
        written.summary(model, &options),
    ))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(generate, m)?)
}
