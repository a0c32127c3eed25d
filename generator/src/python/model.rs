//! `uavgen.Model`: a validated model file, its f(x, u), Jacobians and fixed-step RK4 simulation.

use super::{err, floats, to_bytes};
use crate::discretize::{auto_substeps, discrete_step, Envelope};
use crate::ir::ModelIr;
use crate::model::Model;
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use std::path::PathBuf;

/// A validated `uavgen-model/1` model and its symbolic IR (built once).
#[pyclass(name = "Model", module = "uavgen._uavgen", frozen)]
pub struct PyModel {
    /// The file's text as read or produced (what `to_json` gives back and `save` writes).
    pub text: String,
    /// What errors name: the path the model was read from, or the label given.
    pub label: String,
    pub model: Model,
    pub ir: ModelIr,
}

impl PyModel {
    /// Validate `text` as `uavgen::model::parse` does (the CLI's messages, naming `label`).
    pub fn parse(text: String, label: &str) -> PyResult<Self> {
        let mut model = crate::model::parse(&text, label).map_err(err)?;
        // As `uavgen::load`: the generated crates' provenance names the file, not its directory.
        if let Some(name) = std::path::Path::new(label).file_name() {
            model.source.file = name.to_string_lossy().into_owned();
        }
        Ok(Self::new(text, label.to_owned(), model))
    }

    pub fn new(text: String, label: String, model: Model) -> Self {
        let ir = ModelIr::new(&model);
        Self { text, label, model, ir }
    }

    /// `n` rows of `width` values from bytes, checked.
    fn rows(&self, bytes: &[u8], n: usize, width: usize, what: &str) -> PyResult<Vec<f64>> {
        let v = floats(bytes, what)?;
        if v.len() != n * width {
            return Err(err(format!(
                "{what}: expected {n} rows of {width} values ({}), got {} values",
                if what == "x" {
                    "the model's states"
                } else {
                    "the model's inputs"
                },
                v.len()
            )));
        }
        Ok(v)
    }
}

#[pymethods]
impl PyModel {
    /// Read and validate a model file (`uavgen::load`: errors name the path).
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let model = crate::load(&path).map_err(err)?;
        let label = path.display().to_string();
        let text = std::fs::read_to_string(&path).map_err(|e| err(format!("{label}: cannot read: {e}")))?;
        Ok(Self::new(text, label, model))
    }

    /// Validate model text; `name_for_errors` names it in errors (as a file name would).
    #[staticmethod]
    #[pyo3(signature = (text, name_for_errors = "<model>"))]
    fn from_json(text: String, name_for_errors: &str) -> PyResult<Self> {
        Self::parse(text, name_for_errors)
    }

    /// The model file's text.
    fn to_json(&self) -> String {
        self.text.clone()
    }

    /// Write the model file (atomically); an existing file is replaced only with `force`.
    #[pyo3(signature = (path, force = false))]
    fn save(&self, path: PathBuf, force: bool) -> PyResult<()> {
        if path.exists() && !force {
            return Err(err(format!(
                "{}: exists; pass force=True to overwrite it",
                path.display()
            )));
        }
        crate::sim::write_atomically(&path, &self.text).map_err(err)
    }

    #[getter]
    fn name(&self) -> String {
        self.model.name.clone()
    }
    #[getter]
    fn label(&self) -> String {
        self.label.clone()
    }
    /// All states (the file's, then the extra states of a `corrections` block).
    #[getter]
    fn states(&self) -> Vec<String> {
        self.model.states.clone()
    }
    #[getter]
    fn inputs(&self) -> Vec<String> {
        self.model.inputs.clone()
    }
    /// `sindy` or `pd`.
    #[getter]
    fn kind(&self) -> &'static str {
        self.model.kind_name()
    }
    /// The pure delay of each input in s (the `corrections.latency` block; zeros without it).
    #[getter]
    fn input_delays(&self) -> Vec<f64> {
        self.model.input_delays()
    }
    /// SHA-256 of the model text.
    #[getter]
    fn sha256(&self) -> String {
        self.model.source.sha256.clone()
    }

    /// ẋ = f(x, u) for `n` rows (bytes of n×NX and n×NU f64), as n×NX bytes.
    fn f<'py>(&self, py: Python<'py>, x: &[u8], u: &[u8], n: usize) -> PyResult<Bound<'py, PyBytes>> {
        let (nx, nu) = (self.model.nx(), self.model.nu());
        let x = self.rows(x, n, nx, "x")?;
        let u = self.rows(u, n, nu, "u")?;
        let out: Vec<f64> = py.allow_threads(|| {
            (0..n)
                .flat_map(|k| self.ir.eval_f(&x[k * nx..(k + 1) * nx], &u[k * nu..(k + 1) * nu]))
                .collect()
        });
        Ok(to_bytes(py, &out))
    }

    /// (∂f/∂x, ∂f/∂u) for `n` rows, as n×NX×NX and n×NX×NU bytes (row-major).
    fn jacobians<'py>(
        &self,
        py: Python<'py>,
        x: &[u8],
        u: &[u8],
        n: usize,
    ) -> PyResult<(Bound<'py, PyBytes>, Bound<'py, PyBytes>)> {
        let (nx, nu) = (self.model.nx(), self.model.nu());
        let x = self.rows(x, n, nx, "x")?;
        let u = self.rows(u, n, nu, "u")?;
        let (a, b) = py.allow_threads(|| {
            let (mut a, mut b) = (Vec::with_capacity(n * nx * nx), Vec::with_capacity(n * nx * nu));
            for k in 0..n {
                let (fx, fu) = self
                    .ir
                    .eval_jacobian(&x[k * nx..(k + 1) * nx], &u[k * nu..(k + 1) * nu]);
                a.extend(fx.into_iter().flatten());
                b.extend(fu.into_iter().flatten());
            }
            (a, b)
        });
        Ok((to_bytes(py, &a), to_bytes(py, &b)))
    }

    /// RK4 substeps per sample of `dt` s by the automatic rule (the code generator's and evaluate's).
    fn auto_substeps(&self, dt: f64) -> PyResult<usize> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(err(format!("dt: must be a positive number of seconds, got {dt}")));
        }
        auto_substeps(&self.ir, dt, &Envelope::default())
            .map(|c| c.substeps)
            .map_err(|e| err(format!("{}: choosing RK4 substeps for dt = {dt} s: {e}", self.label)))
    }

    /// Free run from `x0` under `steps` inputs held over samples of `dt` s: fixed-step RK4 with
    /// `substeps` substeps per sample (None: the automatic rule), the discretisation of the
    /// generated crate and of `uavgen evaluate`. Returns (steps + 1)×NX bytes and the substeps.
    #[pyo3(signature = (x0, u, steps, dt, substeps = None))]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        x0: &[u8],
        u: &[u8],
        steps: usize,
        dt: f64,
        substeps: Option<usize>,
    ) -> PyResult<(Bound<'py, PyBytes>, usize)> {
        let (nx, nu) = (self.model.nx(), self.model.nu());
        let x0 = self.rows(x0, 1, nx, "x")?;
        let u = self.rows(u, steps, nu, "u")?;
        let m = match substeps {
            Some(0) => return Err(err("substeps: must be at least 1, got 0")),
            Some(m) => {
                if !(dt.is_finite() && dt > 0.0) {
                    return Err(err(format!("dt: must be a positive number of seconds, got {dt}")));
                }
                m
            }
            None => self.auto_substeps(dt)?,
        };
        let out = py.allow_threads(|| {
            let mut out = Vec::with_capacity((steps + 1) * nx);
            out.extend_from_slice(&x0);
            let mut x = x0;
            for k in 0..steps {
                x = discrete_step(&self.ir, &x, &u[k * nu..(k + 1) * nu], dt, m);
                out.extend_from_slice(&x);
            }
            out
        });
        Ok((to_bytes(py, &out), m))
    }

    fn __repr__(&self) -> String {
        format!(
            "Model(name={:?}, kind={:?}, states={}, inputs={}, source={:?})",
            self.model.name,
            self.model.kind_name(),
            self.model.nx(),
            self.model.nu(),
            self.label
        )
    }
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyModel>()
}
