//! `uavgen import-pysindy`: a PySINDy model (feature names + coefficient
//! matrix, as written by `scripts/export_pysindy.py`) to a `uavgen-model/1` file.

use super::error::{ModelError, ModelErrorKind as K};
use super::file::{Coefficient, SindyFile, DEFAULT_INPUTS, DEFAULT_STATES, FORMAT};
use serde::Deserialize;

/// The export of a fitted `pysindy.SINDy` model.
#[derive(Debug, Deserialize)]
pub struct PysindyExport {
    /// `model.get_feature_names()`
    pub feature_names: Vec<String>,
    /// `model.coefficients()`: one row per target, one column per feature.
    pub coefficients: Vec<Vec<f64>>,
    /// The state fitted by each row (default: all states in order).
    #[serde(default)]
    pub targets: Option<Vec<String>>,
    #[serde(default)]
    pub kinematic: Option<Vec<(String, String)>>,
    #[serde(default)]
    pub states: Option<Vec<String>>,
    #[serde(default)]
    pub inputs: Option<Vec<String>>,
    /// Anything else (versions, settings) is kept as provenance.
    #[serde(flatten)]
    pub extra: serde_json::Map<String, serde_json::Value>,
}

/// How rows that PySINDy did not fit are completed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum KinematicRows {
    /// Each standard position/angle state that is not a target and whose
    /// velocity state exists becomes kinematic (x→vx, …, yaw→yaw_rate).
    #[default]
    Auto,
    /// Only what the export lists.
    None,
}

/// Options of the import.
#[derive(Clone, Debug)]
pub struct ImportOptions {
    pub name: String,
    pub kinematic: KinematicRows,
    /// Coefficients with |Ξ| ≤ this are dropped (PySINDy writes exact zeros).
    pub drop_below: f64,
}

/// Convert an export (its text, `label` naming the file) to a model file.
pub fn import(text: &str, label: &str, options: &ImportOptions) -> Result<SindyFile, ModelError> {
    let export: PysindyExport =
        serde_json::from_str(text).map_err(|e| super::load::json_syntax_error(text, label, &e))?;
    let states = export
        .states
        .clone()
        .unwrap_or_else(|| DEFAULT_STATES.iter().map(|s| s.to_string()).collect());
    let targets = export.targets.clone().unwrap_or_else(|| states.clone());
    if export.coefficients.len() != targets.len() {
        return Err(ModelError::new(
            label,
            "coefficients",
            K::WrongCount,
            format!(
                "{} rows for {} targets ({})",
                export.coefficients.len(),
                targets.len(),
                targets.join(", ")
            ),
        ));
    }
    // Two rows for one state would be merged into one row of the model: refused.
    for (i, t) in targets.iter().enumerate() {
        if let Some(first) = targets[..i].iter().position(|u| u == t) {
            return Err(ModelError::new(
                label,
                format!("targets[{i}]"),
                K::Duplicate,
                format!("'{t}' is already the target of row {first}: each state may be fitted once"),
            ));
        }
    }
    let mut coefficients = Vec::new();
    for (r, (row, target)) in export.coefficients.iter().zip(&targets).enumerate() {
        if row.len() != export.feature_names.len() {
            return Err(ModelError::new(
                label,
                format!("coefficients[{r}]"),
                K::WrongCount,
                format!("{} columns for {} feature names", row.len(), export.feature_names.len()),
            ));
        }
        for (c, (&value, term)) in row.iter().zip(&export.feature_names).enumerate() {
            if !value.is_finite() {
                return Err(ModelError::new(
                    label,
                    format!("coefficients[{r}][{c}]"),
                    K::NonFinite,
                    format!("non-finite coefficient for '{target}', term '{term}'"),
                ));
            }
            if value.abs() > options.drop_below {
                coefficients.push(Coefficient {
                    state: target.clone(),
                    term: term.clone(),
                    coefficient: value,
                });
            }
        }
    }
    let mut kinematic = export.kinematic.clone().unwrap_or_default();
    if options.kinematic == KinematicRows::Auto {
        for (pos, vel) in DEFAULT_STATES[..6].iter().zip(&DEFAULT_STATES[6..]) {
            let listed = kinematic.iter().any(|(s, _)| s == pos);
            let has = |n: &str| states.iter().any(|s| s == n);
            if !listed && has(pos) && has(vel) && !targets.iter().any(|t| t == pos) {
                kinematic.push((pos.to_string(), vel.to_string()));
            }
        }
    }
    let mut provenance = serde_json::Map::new();
    provenance.insert("imported_from".into(), serde_json::Value::String(label.to_owned()));
    provenance.insert("tool".into(), "uavgen import-pysindy".into());
    for (k, v) in export.extra {
        provenance.insert(k, v);
    }
    let default_inputs: Vec<String> = DEFAULT_INPUTS.iter().map(|s| s.to_string()).collect();
    Ok(SindyFile {
        format: FORMAT.into(),
        kind: "sindy".into(),
        name: options.name.clone(),
        states: export.states.filter(|s| s.as_slice() != DEFAULT_STATES),
        inputs: export.inputs.filter(|i| *i != default_inputs),
        provenance: serde_json::Value::Object(provenance),
        library: export.feature_names,
        kinematic,
        coefficients,
    })
}
