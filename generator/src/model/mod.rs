//! Model files (`uavgen-model/1`): parsing and validation into a [`Model`].
//!
//! Parsing is two-stage: the text becomes a JSON value (syntax errors carry a
//! line and column; JSON's missing NaN/Infinity is reported as a non-finite
//! number), then `format` and `kind` are checked and the value is
//! deserialised into the schema of its kind (errors carry the JSON path), and
//! finally the semantic checks run (names, terms, counts, duplicates), and those of the optional
//! `corrections` block ([`Corrections`]) and of the optional `envelope` block
//! ([`DeclaredEnvelope`]).
//!
//! **States of a corrected model.** After loading, [`Model::states`] is the full state vector:
//! the file's states, then the extra states of the corrections (`<input>_lagged` in input order,
//! then `flight_time`). Everything downstream (IR, discretisation, code generation, MPC options)
//! therefore sees one state vector; [`Model::base_states`] is the file's part (the 12 logged
//! states for a corrected model).

pub mod corrections;
pub mod envelope;
mod error;
pub mod file;
mod load;
pub mod pysindy;
pub mod term;

pub use corrections::{attach as attach_corrections, Corrections, Drag, GroundEffect, ThrustDecay};
pub use envelope::DeclaredEnvelope;
pub use error::{ModelError, ModelErrorKind};
pub use file::{Coefficient, PdFile, SindyFile, DEFAULT_INPUTS, DEFAULT_STATES, FORMAT};
pub use load::{load, parse};
pub use term::{parse_term, Base, Term, TermError};

/// Where a model came from: the file name as given and the SHA-256 of its bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Source {
    pub file: String,
    pub sha256: String,
}

/// A validated model.
#[derive(Clone, Debug)]
pub struct Model {
    pub name: String,
    /// All states: the file's, then the extra states of [`Model::corrections`].
    pub states: Vec<String>,
    pub inputs: Vec<String>,
    pub provenance: serde_json::Value,
    pub dynamics: Dynamics,
    /// The validated `corrections` block, if the file has one.
    pub corrections: Option<Corrections>,
    /// The validated `envelope` block (the operating envelope the model was identified on), if
    /// the file has one.
    pub envelope: Option<DeclaredEnvelope>,
    pub source: Source,
}

/// The model-specific part.
#[derive(Clone, Debug)]
pub enum Dynamics {
    Pd(PdParams),
    Sindy(SindySpec),
}

/// The PD model's physical constants and ξ1..ξ16 (index 0 = ξ1).
#[derive(Clone, Debug, PartialEq)]
pub struct PdParams {
    pub mass: f64,
    pub gravity: f64,
    pub xi: [f64; 16],
}

impl PdParams {
    /// ξₖ with the paper's 1-based numbering.
    pub fn xi(&self, k: usize) -> f64 {
        self.xi[k - 1]
    }
}

/// How one state's derivative is given.
#[derive(Clone, Debug, PartialEq)]
pub enum Row {
    /// ẋᵢ = x_j exactly.
    Kinematic(usize),
    /// ẋᵢ = Σ Ξ_{k,i} θ_k with (library index k, Ξ_{k,i}) pairs in library order.
    Sparse(Vec<(usize, f64)>),
}

/// The SINDy model: library Θ and one [`Row`] per state.
#[derive(Clone, Debug, PartialEq)]
pub struct SindySpec {
    pub library: Vec<Term>,
    pub rows: Vec<Row>,
}

impl Model {
    pub fn nx(&self) -> usize {
        self.states.len()
    }
    pub fn nu(&self) -> usize {
        self.inputs.len()
    }
    /// States then inputs: the variable order of the symbolic graph.
    pub fn variables(&self) -> Vec<String> {
        self.states.iter().chain(&self.inputs).cloned().collect()
    }
    /// Number of states the file declares (without the extra states of the corrections).
    pub fn base_nx(&self) -> usize {
        let extra = self
            .corrections
            .as_ref()
            .map_or(0, |c| c.extra_states(&self.inputs).len());
        self.states.len() - extra
    }
    /// The states the file declares, without the extra states of the corrections.
    pub fn base_states(&self) -> &[String] {
        &self.states[..self.base_nx()]
    }
    /// The pure delay of each input in s, in input order (zeros without `corrections.latency`).
    pub fn input_delays(&self) -> Vec<f64> {
        self.inputs
            .iter()
            .map(|u| self.corrections.as_ref().map_or(0.0, |c| c.delay(u)))
            .collect()
    }
    /// `uavgen check`'s description of the corrections: one line per effect; empty without them.
    pub fn corrections_summary(&self) -> Vec<String> {
        self.corrections
            .as_ref()
            .map_or_else(Vec::new, |c| c.summary(&self.inputs))
    }
    pub fn kind_name(&self) -> &'static str {
        match self.dynamics {
            Dynamics::Pd(_) => "pd",
            Dynamics::Sindy(_) => "sindy",
        }
    }
}
