//! The Python bindings (feature `python`): the extension module `uavgen._uavgen` that the pure
//! Python package `generator/python/uavgen` wraps (docs/python.md). Every binding calls the same
//! library function as the matching CLI command; errors become `uavgen.UavgenError` carrying the
//! CLI's message. Arrays cross the boundary as native-endian f64 bytes (numpy's `tobytes()` /
//! `frombuffer`), so the module needs no numpy at build time.

mod diagnose;
mod evaluate;
mod generate;
mod identify;
mod logs;
mod model;
mod simulate;

use pyo3::prelude::*;
use pyo3::types::PyBytes;

pyo3::create_exception!(
    _uavgen,
    UavgenError,
    pyo3::exceptions::PyException,
    "An error of uavgen, with the message the CLI prints (file, field, line)."
);

/// A uavgen error as a Python exception.
pub(crate) fn err(message: impl std::fmt::Display) -> PyErr {
    UavgenError::new_err(message.to_string())
}

/// f64 values from native-endian bytes; `what` names the argument in the error.
pub(crate) fn floats(bytes: &[u8], what: &str) -> PyResult<Vec<f64>> {
    if bytes.len() % 8 != 0 {
        return Err(err(format!(
            "{what}: {} bytes is not a whole number of f64 values",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(8)
        .map(|c| f64::from_ne_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect())
}

/// f64 values as native-endian bytes.
pub(crate) fn to_bytes<'py>(py: Python<'py>, values: &[f64]) -> Bound<'py, PyBytes> {
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_ne_bytes()).collect();
    PyBytes::new(py, &bytes)
}

/// A stale-row policy by its CLI name (`interpolate`, `keep`).
pub(crate) fn stale_policy(name: &str) -> PyResult<crate::logs::StalePolicy> {
    <crate::logs::StalePolicy as clap::ValueEnum>::from_str(name, false)
        .map_err(|_| err(format!("stale: `{name}` is not one of interpolate, keep")))
}

#[pymodule]
#[pyo3(name = "_uavgen")]
fn uavgen_module(module: &Bound<'_, PyModule>) -> PyResult<()> {
    module.add("UavgenError", module.py().get_type::<UavgenError>())?;
    module.add("__version__", env!("CARGO_PKG_VERSION"))?;
    model::register(module)?;
    logs::register(module)?;
    evaluate::register(module)?;
    generate::register(module)?;
    simulate::register(module)?;
    diagnose::register(module)?;
    identify::register(module)?;
    Ok(())
}
