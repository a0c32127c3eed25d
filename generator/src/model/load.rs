//! Reading and validating model files.

use super::error::{ModelError, ModelErrorKind as K};
use super::file::{PdFile, SindyFile, DEFAULT_INPUTS, DEFAULT_STATES, FORMAT};
use super::term::{parse_term, TermError};
use super::{Corrections, Dynamics, Model, PdParams, Row, SindySpec, Source};
use crate::validate;
use serde::de::DeserializeOwned;
use serde_json::Value;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::path::Path;

/// Read and validate a model file.
pub fn load(path: &Path) -> Result<Model, ModelError> {
    let label = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| ModelError::new(&label, "", K::Io, format!("cannot read: {e}")))?;
    let text = String::from_utf8(bytes).map_err(|_| ModelError::new(&label, "", K::Json, "not UTF-8 text"))?;
    let file_name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or(label.clone());
    let mut model = parse(&text, &label)?;
    model.source.file = file_name;
    Ok(model)
}

/// Validate model text; `label` names the file in errors.
pub fn parse(text: &str, label: &str) -> Result<Model, ModelError> {
    let text = crate::validate::strip_bom(text);
    let mut value: Value = serde_json::from_str(text).map_err(|e| json_syntax_error(text, label, &e))?;
    let obj = value
        .as_object_mut()
        .ok_or_else(|| ModelError::new(label, "", K::Json, "the top level must be a JSON object"))?;
    match obj.get("format") {
        None => {
            return Err(ModelError::new(
                label,
                "format",
                K::MissingField,
                "missing field `format`",
            ))
        }
        Some(Value::String(f)) if f == FORMAT => {}
        Some(other) => {
            return Err(ModelError::new(
                label,
                "format",
                K::UnknownFormat,
                format!("unknown format version {other}: this uavgen reads \"{FORMAT}\""),
            ))
        }
    }
    let source = Source {
        file: label.to_owned(),
        sha256: hex_sha256(text.as_bytes()),
    };
    // Every number the model reads is bounded; the kind's own ranges (mass, gravity, ξ,
    // coefficients) are checked first, so that their messages, which name the range, win.
    let huge = validate::first_out_of_range(&Value::Object(obj.clone()), validate::MODEL_MAX_ABS, &["provenance"]);
    // The corrections block belongs to every kind and is read on its own, after the kind's schema.
    let corrections = obj.remove("corrections");
    // So is the envelope, checked against the states (with the corrections' extra states).
    let envelope = obj.remove("envelope");
    let model = match obj.get("kind").cloned() {
        None => Err(ModelError::new(
            label,
            "kind",
            K::MissingField,
            "missing field `kind` (\"pd\" or \"sindy\")",
        )),
        Some(Value::String(k)) if k == "pd" => {
            let file = typed::<PdFile>(value, label, "")?;
            validate_pd(file, corrections_schema(corrections, label)?, label, source)
        }
        Some(Value::String(k)) if k == "sindy" => {
            let file = typed::<SindyFile>(value, label, "")?;
            validate_sindy(file, corrections_schema(corrections, label)?, label, source)
        }
        Some(other) => Err(ModelError::new(
            label,
            "kind",
            K::UnknownKind,
            format!("unknown kind {other}: expected \"pd\" or \"sindy\""),
        )),
    }?;
    let mut model = model;
    if let Some(v) = &envelope {
        model.envelope = Some(super::envelope::parse(v, label, &model.states)?);
    }
    if let Some((path, v)) = huge {
        return Err(ModelError::new(
            label,
            path,
            K::BadValue,
            format!(
                "{} is out of range: every number of a model file must be within ±{} (docs/model-format.md#ranges)",
                validate::short(v),
                validate::short(validate::MODEL_MAX_ABS)
            ),
        ));
    }
    Ok(model)
}

fn corrections_schema(value: Option<Value>, label: &str) -> Result<Option<Corrections>, ModelError> {
    match value {
        None => Ok(None),
        // serde would also read a struct from an array, by position: only objects are allowed.
        Some(v) if !v.is_object() => Err(ModelError::new(
            label,
            "corrections",
            K::BadValue,
            format!("expected an object, found {v}"),
        )),
        Some(v) => typed::<Corrections>(v, label, "corrections").map(Some),
    }
}

pub(crate) fn hex_sha256(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

pub(crate) fn json_syntax_error(text: &str, label: &str, e: &serde_json::Error) -> ModelError {
    let at = format!("line {}, column {}", e.line(), e.column());
    // JSON has no NaN/Infinity; Python's json module writes them anyway.
    let line = text.lines().nth(e.line().saturating_sub(1)).unwrap_or("");
    let col = e.column().saturating_sub(1).min(line.len());
    let rest = line.get(col..).unwrap_or("").trim_start_matches(['-', '+']);
    let prev = line.get(..col).unwrap_or("");
    let msg = e.to_string();
    if ["NaN", "Infinity", "inf", "nan"]
        .iter()
        .any(|t| rest.starts_with(t) || prev.ends_with(t))
        || msg.contains("out of range")
    {
        return ModelError::new(
            label,
            at,
            K::NonFinite,
            "non-finite number (NaN or infinite): every number in a model file must be finite",
        );
    }
    let msg = msg.split(" at line ").next().unwrap_or(&msg).to_owned();
    ModelError::new(label, at, K::Json, format!("invalid JSON: {msg}"))
}

/// Deserialise `value` into the schema `T`; errors carry the JSON path below `prefix`.
fn typed<T: DeserializeOwned>(value: Value, label: &str, prefix: &str) -> Result<T, ModelError> {
    serde_path_to_error::deserialize::<_, T>(value).map_err(|e| {
        let path = e.path().to_string();
        let mut inner = e.into_inner().to_string();
        let top_level = prefix.is_empty() && !path.contains(['.', '[']);
        if top_level && inner.starts_with("unknown field") && inner.contains("expected one of") {
            // `corrections` is valid at the top level of every kind but read separately.
            inner.push_str(", `corrections`, `envelope`");
        }
        let kind = if inner.starts_with("missing field") {
            K::MissingField
        } else if inner.starts_with("unknown field") {
            K::UnknownField
        } else {
            K::BadValue
        };
        let path = match (path.as_str(), prefix) {
            (".", _) => prefix.to_string(),
            (_, "") => path,
            (_, _) if path.starts_with('[') => format!("{prefix}{path}"),
            _ => format!("{prefix}.{path}"),
        };
        ModelError::new(label, path, kind, inner)
    })
}

fn finite(label: &str, field: &str, v: f64) -> Result<f64, ModelError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ModelError::new(
            label,
            field,
            K::NonFinite,
            format!("non-finite value {v}"),
        ))
    }
}

/// State and input names: defaults, counts, identifiers, uniqueness.
fn names(
    label: &str,
    states: Option<Vec<String>>,
    inputs: Option<Vec<String>>,
    fixed: bool,
) -> Result<(Vec<String>, Vec<String>), ModelError> {
    let states = states.unwrap_or_else(|| DEFAULT_STATES.iter().map(|s| s.to_string()).collect());
    let inputs = inputs.unwrap_or_else(|| DEFAULT_INPUTS.iter().map(|s| s.to_string()).collect());
    if fixed && states.len() != 12 {
        return Err(ModelError::new(
            label,
            "states",
            K::WrongCount,
            format!("the PD model has 12 states, found {}", states.len()),
        ));
    }
    if fixed && inputs.len() != 4 {
        return Err(ModelError::new(
            label,
            "inputs",
            K::WrongCount,
            format!("the PD model has 4 inputs, found {}", inputs.len()),
        ));
    }
    if states.is_empty() {
        return Err(ModelError::new(
            label,
            "states",
            K::WrongCount,
            "at least one state is required",
        ));
    }
    let mut seen = HashMap::new();
    for (field, list) in [("states", &states), ("inputs", &inputs)] {
        for (i, name) in list.iter().enumerate() {
            let loc = format!("{field}[{i}]");
            let valid = name.chars().next().is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
            if !valid || name == "sin" || name == "cos" {
                return Err(ModelError::new(
                    label,
                    loc,
                    K::BadValue,
                    format!("'{name}' is not a valid variable name (letters, digits, '_'; not sin/cos)"),
                ));
            }
            if let Some(first) = seen.insert(name.clone(), loc.clone()) {
                return Err(ModelError::new(
                    label,
                    loc,
                    K::Duplicate,
                    format!("variable '{name}' already declared at {first}"),
                ));
            }
        }
    }
    Ok((states, inputs))
}

fn validate_pd(f: PdFile, corrections: Option<Corrections>, label: &str, source: Source) -> Result<Model, ModelError> {
    let (states, inputs) = names(label, f.states, f.inputs, true)?;
    let mass = finite(label, "mass", f.mass)?;
    let gravity = finite(label, "gravity", f.gravity)?;
    if mass <= 0.0 {
        return Err(ModelError::new(
            label,
            "mass",
            K::BadValue,
            format!("mass must be positive, found {}", validate::short(mass)),
        ));
    }
    validate::within(mass, validate::MASS_KG, "kg")
        .map_err(|m| ModelError::new(label, "mass", K::BadValue, format!("mass {m}")))?;
    validate::within(gravity, validate::GRAVITY, "m/s²")
        .map_err(|m| ModelError::new(label, "gravity", K::BadValue, format!("gravity {m}")))?;
    let mut xi = [0.0; 16];
    match &f.xi {
        Value::Array(items) => {
            if items.len() != 16 {
                return Err(ModelError::new(
                    label,
                    "xi",
                    K::WrongCount,
                    format!("expected 16 values ξ1..ξ16, found {}", items.len()),
                ));
            }
            for (k, item) in items.iter().enumerate() {
                xi[k] = number(label, &format!("xi[{k}]"), item)?;
            }
        }
        Value::Object(map) => {
            for key in map.keys() {
                let ok = key
                    .strip_prefix("xi")
                    .and_then(|n| n.parse::<usize>().ok())
                    .is_some_and(|n| (1..=16).contains(&n) && key == &format!("xi{n}"));
                if !ok {
                    return Err(ModelError::new(
                        label,
                        format!("xi.{key}"),
                        K::UnknownField,
                        format!("unknown parameter '{key}': expected xi1..xi16"),
                    ));
                }
            }
            for (k, slot) in xi.iter_mut().enumerate() {
                let key = format!("xi{}", k + 1);
                let item = map.get(&key).ok_or_else(|| {
                    ModelError::new(
                        label,
                        format!("xi.{key}"),
                        K::MissingField,
                        format!("missing parameter `{key}`"),
                    )
                })?;
                *slot = number(label, &format!("xi.{key}"), item)?;
            }
        }
        _ => {
            return Err(ModelError::new(
                label,
                "xi",
                K::BadValue,
                "expected an array of 16 numbers or an object with keys xi1..xi16",
            ))
        }
    }
    let p = PdParams { mass, gravity, xi };
    // Locations name ξk the way the file wrote it.
    let loc = |k: usize| {
        if f.xi.is_array() {
            format!("xi[{}]", k - 1)
        } else {
            format!("xi.xi{k}")
        }
    };
    for k in 1..=16 {
        validate::bounded(p.xi(k), validate::XI_MAX_ABS)
            .map_err(|m| ModelError::new(label, loc(k), K::BadValue, format!("ξ{k} {m}")))?;
    }
    for (k, what) in [(14, "Ix"), (15, "Iy"), (16, "Iz")] {
        if p.xi(k) <= 0.0 {
            return Err(ModelError::new(
                label,
                loc(k),
                K::BadValue,
                format!("ξ{k} = {what} is an inertia and must be positive, found {}", p.xi(k)),
            ));
        }
    }
    // (m I + ξ11 b e3ᵀ) is singular where m + ξ11 cos φ cos θ = 0; cos φ cos θ
    // ranges over [−1, 1], so |ξ11| < m keeps it invertible at every attitude.
    if p.xi(11).abs() >= mass {
        return Err(ModelError::new(label, loc(11), K::BadValue, format!("|ξ11| = {} ≥ m = {mass}: m + ξ11 cos φ cos θ vanishes at some attitude and the translational mass matrix is singular", p.xi(11).abs())));
    }
    // M(Ω) + diag(0, 0, ξ12) is positive definite wherever M(Ω) is (|θ| < π/2) iff ξ12 ≥ 0.
    if p.xi(12) < 0.0 {
        return Err(ModelError::new(label, loc(12), K::BadValue, format!("ξ12 = {} < 0: M(Ω) + diag(0, 0, ξ12) becomes singular at attitudes where M(Ω) is not (yaw acceleration feedback must be ≥ 0)", p.xi(12))));
    }
    let base = Model {
        name: f.name,
        states,
        inputs,
        provenance: f.provenance,
        dynamics: Dynamics::Pd(p),
        corrections: None,
        envelope: None,
        source,
    };
    finish(base, corrections, label)
}

/// The last checks, common to every kind: the corrections block (whose extra states are appended
/// to the states), then the name.
fn finish(mut model: Model, corrections: Option<Corrections>, label: &str) -> Result<Model, ModelError> {
    if let Some(c) = &corrections {
        c.validate(label, &model.states, &model.inputs)?;
        model.states.extend(c.extra_states(&model.inputs));
    }
    model.corrections = corrections;
    model.name = name(label, std::mem::take(&mut model.name))?;
    for (what, n, max) in [
        ("states", model.states.len(), validate::MAX_STATES),
        ("inputs", model.inputs.len(), validate::MAX_INPUTS),
    ] {
        if n > max {
            return Err(ModelError::new(
                label,
                what,
                K::WrongCount,
                format!("{n} {what}: at most {max} are supported (with the extra states of the corrections; docs/model-format.md#ranges)"),
            ));
        }
    }
    if let Dynamics::Sindy(s) = &model.dynamics {
        let coefficients: usize = s
            .rows
            .iter()
            .map(|r| match r {
                Row::Sparse(entries) => entries.len(),
                Row::Kinematic(_) => 0,
            })
            .sum();
        if coefficients > validate::MAX_COEFFICIENTS {
            return Err(ModelError::new(
                label,
                "coefficients",
                K::WrongCount,
                format!(
                    "{coefficients} coefficients: at most {} are supported (the generated code grows with them; docs/model-format.md#ranges)",
                    validate::MAX_COEFFICIENTS
                ),
            ));
        }
        if s.library.len() > validate::MAX_LIBRARY_TERMS {
            return Err(ModelError::new(
                label,
                "library",
                K::WrongCount,
                format!(
                    "{} library terms: at most {} are supported (docs/model-format.md#ranges)",
                    s.library.len(),
                    validate::MAX_LIBRARY_TERMS
                ),
            ));
        }
    }
    Ok(model)
}

fn number(label: &str, loc: &str, v: &Value) -> Result<f64, ModelError> {
    let x = v
        .as_f64()
        .ok_or_else(|| ModelError::new(label, loc, K::BadValue, format!("expected a number, found {v}")))?;
    finite(label, loc, x)
}

fn name(label: &str, name: String) -> Result<String, ModelError> {
    if name.trim().is_empty() {
        return Err(ModelError::new(
            label,
            "name",
            K::BadValue,
            "the model name must not be empty",
        ));
    }
    Ok(name)
}

fn term_error(label: &str, loc: String, text: &str, e: TermError) -> ModelError {
    let kind = match e {
        TermError::Syntax(_) => K::BadTerm,
        TermError::UnknownVariable(_) => K::UnknownVariable,
    };
    ModelError::new(label, loc, kind, format!("{e} in term '{text}'"))
}

fn validate_sindy(
    f: SindyFile,
    corrections: Option<Corrections>,
    label: &str,
    source: Source,
) -> Result<Model, ModelError> {
    let (states, inputs) = names(label, f.states, f.inputs, false)?;
    let vars: Vec<String> = states.iter().chain(&inputs).cloned().collect();
    let state_index = |loc: String, s: &str| {
        states.iter().position(|n| n == s).ok_or_else(|| {
            let kind = if inputs.iter().any(|n| n == s) {
                K::BadValue
            } else {
                K::UnknownVariable
            };
            ModelError::new(
                label,
                loc,
                kind,
                format!("'{s}' is not a state (states: {})", states.join(", ")),
            )
        })
    };
    let mut library = Vec::with_capacity(f.library.len());
    let mut by_term = HashMap::new();
    for (i, text) in f.library.iter().enumerate() {
        let loc = format!("library[{i}]");
        let term = parse_term(text, &vars).map_err(|e| term_error(label, loc.clone(), text, e))?;
        if let Some(first) = by_term.insert(term.clone(), i) {
            return Err(ModelError::new(
                label,
                loc,
                K::Duplicate,
                format!("term '{text}' duplicates library[{first}] ('{}')", f.library[first]),
            ));
        }
        library.push(term);
    }
    let mut rows: Vec<Option<Row>> = vec![None; states.len()];
    for (i, (state, derivative)) in f.kinematic.iter().enumerate() {
        let si = state_index(format!("kinematic[{i}][0]"), state)?;
        let di = state_index(format!("kinematic[{i}][1]"), derivative)?;
        if rows[si].is_some() {
            return Err(ModelError::new(
                label,
                format!("kinematic[{i}]"),
                K::Duplicate,
                format!("state '{state}' is listed as kinematic twice"),
            ));
        }
        rows[si] = Some(Row::Kinematic(di));
    }
    let mut entries: HashMap<(usize, usize), usize> = HashMap::new();
    let mut sparse: Vec<Vec<(usize, f64)>> = vec![Vec::new(); states.len()];
    for (i, c) in f.coefficients.iter().enumerate() {
        let loc = format!("coefficients[{i}]");
        let si = state_index(format!("{loc}.state"), &c.state)?;
        let term = parse_term(&c.term, &vars).map_err(|e| term_error(label, format!("{loc}.term"), &c.term, e))?;
        let ti = *by_term.get(&term).ok_or_else(|| {
            ModelError::new(
                label,
                format!("{loc}.term"),
                K::UnknownVariable,
                format!("term '{}' is not in the library", c.term),
            )
        })?;
        finite(label, &format!("{loc}.coefficient"), c.coefficient)?;
        validate::bounded(c.coefficient, validate::COEFFICIENT_MAX_ABS).map_err(|m| {
            ModelError::new(
                label,
                format!("{loc}.coefficient"),
                K::BadValue,
                format!("a coefficient {m}"),
            )
        })?;
        if matches!(rows[si], Some(Row::Kinematic(_))) {
            return Err(ModelError::new(
                label,
                loc,
                K::Duplicate,
                format!(
                    "state '{}' is kinematic: its row cannot also have coefficients",
                    c.state
                ),
            ));
        }
        if let Some(first) = entries.insert((si, ti), i) {
            return Err(ModelError::new(
                label,
                loc,
                K::Duplicate,
                format!(
                    "duplicate entry for state '{}', term '{}' (first at coefficients[{first}])",
                    c.state, c.term
                ),
            ));
        }
        sparse[si].push((ti, c.coefficient));
    }
    let rows = rows
        .into_iter()
        .zip(sparse)
        .map(|(row, mut entries)| {
            row.unwrap_or_else(|| {
                entries.sort_by_key(|&(t, _)| t);
                Row::Sparse(entries)
            })
        })
        .collect();
    let base = Model {
        name: f.name,
        states,
        inputs,
        provenance: f.provenance,
        dynamics: Dynamics::Sindy(SindySpec { library, rows }),
        corrections: None,
        envelope: None,
        source,
    };
    finish(base, corrections, label)
}
