//! The on-disk JSON schema of `uavgen-model/1` (serde), before validation.

use serde::{Deserialize, Serialize};

pub const FORMAT: &str = "uavgen-model/1";

/// The 12 states of `LOG_FORMAT.md`, in order.
pub const DEFAULT_STATES: [&str; 12] = [
    "x",
    "y",
    "z",
    "roll",
    "pitch",
    "yaw",
    "vx",
    "vy",
    "vz",
    "roll_rate",
    "pitch_rate",
    "yaw_rate",
];
/// The 4 autopilot commands of `LOG_FORMAT.md`, in order.
pub const DEFAULT_INPUTS: [&str; 4] = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"];

/// `kind: "pd"` — the paper's PD/Euler-Lagrange model.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PdFile {
    pub format: String,
    pub kind: String,
    pub name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub states: Option<Vec<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inputs: Option<Vec<String>>,
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub provenance: serde_json::Value,
    /// kg
    pub mass: f64,
    /// m/s²
    pub gravity: f64,
    /// 16 numbers in order ξ1..ξ16, or an object with keys "xi1".."xi16".
    pub xi: serde_json::Value,
}

/// One non-zero entry of Ξ.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Coefficient {
    pub state: String,
    pub term: String,
    pub coefficient: f64,
}

/// `kind: "sindy"` — ẋ = Ξᵀ Θ(x, u).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SindyFile {
    pub format: String,
    pub kind: String,
    pub name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub states: Option<Vec<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inputs: Option<Vec<String>>,
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub provenance: serde_json::Value,
    /// Candidate functions Θ, as term strings.
    pub library: Vec<String>,
    /// Rows whose derivative is another state exactly: `[state, derivative]`.
    #[serde(default)]
    pub kinematic: Vec<(String, String)>,
    /// Sparse Ξ.
    pub coefficients: Vec<Coefficient>,
}
