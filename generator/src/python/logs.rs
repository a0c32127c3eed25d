//! `uavgen.Log`: a validated flight log (the CSV contract, or a recording imported with a
//! profile), its arrays, and logs built from arrays.

use super::{err, floats, to_bytes};
use crate::logs::{FlightLog, INPUT_COLUMNS, STATE_COLUMNS};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use std::fmt::Write as _;
use std::path::PathBuf;

/// A validated flight log: segments of t, the 12 states (yaw unwrapped) and the 4 inputs.
#[pyclass(name = "Log", module = "uavgen._uavgen", frozen)]
pub struct PyLog {
    pub log: FlightLog,
}

/// The segments' arrays: (t, x, u, battery voltage or None, rows, first line) of one segment.
type SegmentArrays<'py> = (
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    Bound<'py, PyBytes>,
    Option<Bound<'py, PyBytes>>,
    usize,
    usize,
);

impl PyLog {
    fn parse(text: &str, label: &str) -> PyResult<Self> {
        let log = crate::logs::parse_log(text, label).map_err(err)?;
        crate::logs::refuse_degrees(&log).map_err(err)?;
        Ok(Self { log })
    }
}

/// The CSV text of a log: its metadata, the contract's columns, `battery_voltage` if present and
/// `segment` (the segment's index).
pub fn to_csv(log: &FlightLog) -> String {
    let battery = log.segments.iter().all(|s| s.battery_voltage.is_some()) && !log.segments.is_empty();
    let mut out = String::new();
    for (k, v) in &log.metadata {
        let _ = writeln!(out, "# {k}: {v}");
    }
    out.push('t');
    for c in STATE_COLUMNS.iter().chain(INPUT_COLUMNS.iter()) {
        out.push(',');
        out.push_str(c);
    }
    out.push_str(if battery {
        ",battery_voltage,segment\n"
    } else {
        ",segment\n"
    });
    for s in &log.segments {
        for k in 0..s.len() {
            let _ = write!(out, "{}", s.t[k]);
            for v in s.x[k].iter().chain(s.u[k].iter()) {
                let _ = write!(out, ",{v}");
            }
            if let Some(b) = s.battery_voltage.as_ref().filter(|_| battery) {
                let _ = write!(out, ",{}", b.get(k).copied().unwrap_or(f64::NAN));
            }
            let _ = writeln!(out, ",{}", s.index);
        }
    }
    out
}

#[pymethods]
impl PyLog {
    /// Read a flight log as `--log` (and `--profile`) of identify, evaluate and diagnose do
    /// (`uavgen::logs::load_any`): errors name the path, line and column.
    #[staticmethod]
    #[pyo3(signature = (path, profile = None))]
    fn load(py: Python<'_>, path: PathBuf, profile: Option<String>) -> PyResult<Self> {
        let log = py
            .allow_threads(|| crate::logs::load_any(&path, profile.as_deref()))
            .map_err(err)?;
        Ok(Self { log })
    }

    /// Validate CSV text of the contract; `label` names it in errors and is the log's source.
    #[staticmethod]
    #[pyo3(signature = (text, label = "<csv>"))]
    fn from_csv(text: &str, label: &str) -> PyResult<Self> {
        Self::parse(text, label)
    }

    /// A log from arrays: `t` (n), `x` (n×12), `u` (n×4) as f64 bytes; optional `segment` (n
    /// integers), `battery_voltage` (n f64 bytes) and metadata pairs (e.g. `rate_hz`). Written as
    /// the contract's CSV and validated by the same reader as a file.
    #[staticmethod]
    #[pyo3(signature = (t, x, u, n, segment = None, battery_voltage = None, metadata = Vec::new(), label = "<arrays>"))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        t: &[u8],
        x: &[u8],
        u: &[u8],
        n: usize,
        segment: Option<Vec<i64>>,
        battery_voltage: Option<&[u8]>,
        metadata: Vec<(String, String)>,
        label: &str,
    ) -> PyResult<Self> {
        let t = floats(t, "t")?;
        let x = floats(x, "x")?;
        let u = floats(u, "u")?;
        let battery = battery_voltage.map(|b| floats(b, "battery_voltage")).transpose()?;
        for (what, len, width) in [("t", t.len(), 1), ("x", x.len(), 12), ("u", u.len(), 4)] {
            if len != n * width {
                return Err(err(format!(
                    "{what}: expected {n} rows of {width} values, got {len} values"
                )));
            }
        }
        if segment.as_ref().is_some_and(|s| s.len() != n) {
            return Err(err(format!("segment: expected {n} values")));
        }
        if battery.as_ref().is_some_and(|b| b.len() != n) {
            return Err(err(format!("battery_voltage: expected {n} values")));
        }
        let mut text = String::with_capacity(n * 200 + 256);
        for (k, v) in &metadata {
            if k.contains(['\n', ':']) || v.contains('\n') {
                return Err(err(format!(
                    "metadata: `{k}` cannot be written as a `# key: value` line"
                )));
            }
            let _ = writeln!(text, "# {k}: {v}");
        }
        text.push('t');
        for c in STATE_COLUMNS.iter().chain(INPUT_COLUMNS.iter()) {
            text.push(',');
            text.push_str(c);
        }
        if battery.is_some() {
            text.push_str(",battery_voltage");
        }
        text.push_str(if segment.is_some() { ",segment\n" } else { "\n" });
        for k in 0..n {
            let _ = write!(text, "{}", t[k]);
            for v in x[k * 12..(k + 1) * 12].iter().chain(&u[k * 4..(k + 1) * 4]) {
                let _ = write!(text, ",{v}");
            }
            if let Some(b) = &battery {
                let _ = write!(text, ",{}", b[k]);
            }
            if let Some(s) = &segment {
                let _ = write!(text, ",{}", s[k]);
            }
            text.push('\n');
        }
        Self::parse(&text, label)
    }

    /// The log as the contract's CSV text (yaw unwrapped, one `segment` value per segment).
    fn to_csv(&self) -> String {
        to_csv(&self.log)
    }

    /// What errors and reports name the log by (the path as given).
    #[getter]
    fn source(&self) -> String {
        self.log.source.clone()
    }
    /// The `# key: value` lines, in file order.
    #[getter]
    fn metadata(&self) -> Vec<(String, String)> {
        self.log.metadata.clone()
    }
    /// Data rows over all segments.
    #[getter]
    fn rows(&self) -> usize {
        self.log.rows()
    }
    #[getter]
    fn segment_count(&self) -> usize {
        self.log.segments.len()
    }
    /// The quality report's warnings (irregular sampling, rate mismatch, stale rows, …).
    fn warnings(&self) -> Vec<String> {
        self.log.report.warnings()
    }

    /// One segment's arrays as bytes: (t, x, u, battery voltage or None, rows, first line).
    fn segment<'py>(&self, py: Python<'py>, i: usize) -> PyResult<SegmentArrays<'py>> {
        let s = self
            .log
            .segments
            .get(i)
            .ok_or_else(|| err(format!("segment {i}: the log has {}", self.log.segments.len())))?;
        let x: Vec<f64> = s.x.iter().flatten().copied().collect();
        let u: Vec<f64> = s.u.iter().flatten().copied().collect();
        Ok((
            to_bytes(py, &s.t),
            to_bytes(py, &x),
            to_bytes(py, &u),
            s.battery_voltage.as_ref().map(|b| to_bytes(py, b)),
            s.len(),
            s.first_line,
        ))
    }

    fn __repr__(&self) -> String {
        format!(
            "Log(source={:?}, rows={}, segments={})",
            self.log.source,
            self.log.rows(),
            self.log.segments.len()
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLog>()
}
