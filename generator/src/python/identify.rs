//! `uavgen.identify`: `uavgen identify`'s code path (crate::identify::pipeline).

use super::err;
use super::logs::PyLog;
use super::stale_policy;
use crate::identify::dataset::Targets;
use crate::identify::pipeline::{self, IdentifyOptions, Method, OptimizerChoice, Report};
use crate::identify::sindy::{Criterion, LibraryKind};
use pyo3::prelude::*;
use std::cell::RefCell;

/// Identification's messages: kept, and with `progress` also printed on stderr as they come
/// (no bars).
struct Collect {
    lines: RefCell<Vec<String>>,
    progress: bool,
}

impl Report for Collect {
    fn line(&self, text: &str) {
        if self.progress {
            eprintln!("{text}");
        }
        self.lines.borrow_mut().push(text.to_string());
    }
    fn begin(&self, what: &str, _steps: Option<usize>) {
        if self.progress {
            eprintln!("{what} ...");
        }
    }
}

/// Identify a model from `logs` with `uavgen identify`'s options (the flags' names, underscores
/// for dashes; the CLI's defaults): (the model file's text, its warnings, the messages the CLI
/// prints on stderr).
#[pyfunction]
#[pyo3(signature = (logs, method, name, out_label = None, savgol_window = None, savgol_order = 3, library = "physics", all_rows = false, optimizer = "stlsq", threshold = None, sweep = false, sweep_values = None, alpha = None, horizon_check = true, criterion = "bic", input_delay = "auto".to_string(), stale = "interpolate", targets = None, refine_loops = true, mass = 2.4, lowpass = None, max_rate = crate::logs::resample::DEFAULT_MAX_RATE_HZ, progress = false))]
#[allow(clippy::too_many_arguments)]
fn identify(
    py: Python<'_>,
    logs: Vec<PyRef<'_, PyLog>>,
    method: &str,
    name: &str,
    out_label: Option<String>,
    savgol_window: Option<usize>,
    savgol_order: usize,
    library: &str,
    all_rows: bool,
    optimizer: &str,
    threshold: Option<f64>,
    sweep: bool,
    sweep_values: Option<Vec<f64>>,
    alpha: Option<f64>,
    horizon_check: bool,
    criterion: &str,
    input_delay: String,
    stale: &str,
    targets: Option<&str>,
    refine_loops: bool,
    mass: f64,
    lowpass: Option<f64>,
    max_rate: f64,
    progress: bool,
) -> PyResult<(String, Vec<String>, Vec<String>)> {
    let one_of =
        |what: &str, value: &str, names: &[&str]| err(format!("{what}: `{value}` is not one of {}", names.join(", ")));
    let method = match method {
        "sindy" => Method::Sindy,
        "pd" => Method::Pd,
        other => return Err(one_of("method", other, &["sindy", "pd"])),
    };
    let options = IdentifyOptions {
        out_label: out_label.unwrap_or_else(|| name.to_string()),
        savgol_window,
        savgol_order,
        library: match library {
            "physics" => LibraryKind::Physics,
            "paper" => LibraryKind::Paper,
            other => return Err(one_of("library", other, &["physics", "paper"])),
        },
        all_rows,
        optimizer: match optimizer {
            "stlsq" => OptimizerChoice::Stlsq,
            "sr3-l0" | "sr3_l0" => OptimizerChoice::Sr3L0,
            "sr3-l1" | "sr3_l1" => OptimizerChoice::Sr3L1,
            other => return Err(one_of("optimizer", other, &["stlsq", "sr3-l0", "sr3-l1"])),
        },
        threshold,
        sweep,
        sweep_values,
        alpha,
        horizon_check,
        criterion: match criterion {
            "bic" => Criterion::Bic,
            "aic" => Criterion::Aic,
            other => return Err(one_of("criterion", other, &["bic", "aic"])),
        },
        input_delay,
        stale: stale_policy(stale)?,
        targets: match targets {
            None => None,
            Some("derivative") => Some(Targets::SavGol),
            Some("integral") => Some(Targets::Trapezoid),
            Some(other) => return Err(one_of("targets", other, &["derivative", "integral"])),
        },
        refine_loops,
        mass,
        lowpass,
        max_rate_hz: max_rate,
        ..IdentifyOptions::new(method, name)
    };
    options.validate().map_err(err)?;
    if logs.is_empty() {
        return Err(err("logs: at least one flight log is needed"));
    }
    let logs: Vec<_> = logs.iter().map(|l| l.log.clone()).collect();
    py.allow_threads(|| {
        let report = Collect {
            lines: RefCell::new(Vec::new()),
            progress,
        };
        let identified = pipeline::identify(logs, &options, &report)?;
        Ok((identified.json, identified.warnings, report.lines.into_inner()))
    })
    .map_err(|e: String| err(e))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(identify, m)?)
}
