//! The optional `envelope` block of a model file: the operating envelope the model was identified
//! on, `[lo, hi]` per state (docs/model-format.md#envelope).
//!
//! The generated MPC reports `OutOfEnvelope` when x₀ or the reference leaves it
//! (`ENVELOPE_LO`/`ENVELOPE_HI` of the crate, docs/mpc.md#plausibility); states the block does not
//! name keep the generator's generic bounds. `uavgen identify` writes the block from its training
//! logs ([`from_logs`]): the observed range per state, widened by a margin.

use super::error::{ModelError, ModelErrorKind as K};
use crate::logs::{FlightLog, STATE_COLUMNS};
use crate::validate;
use serde_json::Value;

/// Largest |lo|, |hi| of a declared bound (any unit; far beyond a quadrotor's states).
pub const ENVELOPE_MAX_ABS: f64 = 1e6;
/// Roll and pitch bounds must lie within ±this (rad): the Euler angles are singular at ±π/2.
pub const TILT_MAX_ABS: f64 = std::f64::consts::FRAC_PI_2;
/// The margin of an identified envelope: the observed range [min, max] becomes
/// [min − m, max + m] with m = `MARGIN_FACTOR` · (max − min)/2 + the state's floor
/// ([`margin_floor`]). With 2, each side extends by the observed width plus the floor: the
/// envelope is five times as wide as the data. Closed loops that saturate the inputs (the model
/// flown as its own plant at the MPC's tilt bound, 0.611 rad) reach about 2.5 times the M100
/// logs' body rates; a factor of 1 flagged them.
pub const MARGIN_FACTOR: f64 = 2.0;
/// Identified roll and pitch bounds are capped at ±this (rad; the generic plausibility bound).
pub const IDENTIFIED_TILT_CAP: f64 = 1.5;

/// The states an identified envelope bounds, with the absolute floor of their margin (units of
/// the state: rad, m/s, rad/s). Positions are left out (the models are translation-invariant:
/// where the vehicle flew says nothing about where the model holds), and so is yaw (unwrapped,
/// the models depend on it through sin/cos only); they keep the generic bounds.
pub fn margin_floor(state: &str) -> Option<f64> {
    match state {
        "roll" | "pitch" => Some(0.1),
        "vx" | "vy" | "vz" => Some(0.5),
        "roll_rate" | "pitch_rate" | "yaw_rate" => Some(0.5),
        _ => None,
    }
}

/// Declared bounds `(state, lo, hi)`, in the model's state order.
#[derive(Clone, Debug, PartialEq)]
pub struct DeclaredEnvelope {
    pub bounds: Vec<(String, f64, f64)>,
}

impl DeclaredEnvelope {
    /// The declared [lo, hi] of `state`, if any.
    pub fn get(&self, state: &str) -> Option<(f64, f64)> {
        self.bounds
            .iter()
            .find(|(s, _, _)| s == state)
            .map(|&(_, lo, hi)| (lo, hi))
    }

    /// The block as JSON text, one state per line (`"vx": [-13.4, 13.4]`), indented for the
    /// top level of a model file.
    pub fn to_json_text(&self) -> String {
        let num = |v: f64| serde_json::to_string(&v).unwrap_or_else(|_| "0".into());
        let lines: Vec<String> = self
            .bounds
            .iter()
            .map(|(s, lo, hi)| format!("    \"{s}\": [{}, {}]", num(*lo), num(*hi)))
            .collect();
        format!("{{\n{}\n  }}", lines.join(",\n"))
    }
}

/// Validate the `envelope` value of a model file whose states (with the extra states of its
/// corrections) are `states`.
pub fn parse(value: &Value, label: &str, states: &[String]) -> Result<DeclaredEnvelope, ModelError> {
    let Value::Object(map) = value else {
        return Err(ModelError::new(
            label,
            "envelope",
            K::BadValue,
            format!("expected an object {{\"<state>\": [lo, hi], ...}}, found {value}"),
        ));
    };
    if map.is_empty() {
        return Err(ModelError::new(
            label,
            "envelope",
            K::BadValue,
            "an empty envelope declares nothing: give [lo, hi] for some states, or remove it",
        ));
    }
    let mut bounds = Vec::new();
    for (state, item) in map {
        let loc = format!("envelope.{state}");
        if !states.iter().any(|s| s == state) {
            return Err(ModelError::new(
                label,
                loc,
                K::UnknownVariable,
                format!("'{state}' is not a state of the model (states: {})", states.join(", ")),
            ));
        }
        let pair = match item {
            Value::Array(a) if a.len() == 2 => a,
            other => {
                return Err(ModelError::new(
                    label,
                    loc,
                    K::BadValue,
                    format!("expected [lo, hi] (two numbers), found {other}"),
                ))
            }
        };
        let mut lohi = [0.0; 2];
        for (i, v) in pair.iter().enumerate() {
            let at = format!("{loc}[{i}]");
            let x = v
                .as_f64()
                .ok_or_else(|| ModelError::new(label, &at, K::BadValue, format!("expected a number, found {v}")))?;
            validate::bounded(x, ENVELOPE_MAX_ABS)
                .map_err(|m| ModelError::new(label, &at, K::BadValue, format!("an envelope bound {m}")))?;
            lohi[i] = x;
        }
        let [lo, hi] = lohi;
        if lo >= hi {
            return Err(ModelError::new(
                label,
                loc,
                K::BadValue,
                format!(
                    "lo must be below hi, found [{}, {}]",
                    validate::short(lo),
                    validate::short(hi)
                ),
            ));
        }
        if (state == "roll" || state == "pitch") && (lo < -TILT_MAX_ABS || hi > TILT_MAX_ABS) {
            return Err(ModelError::new(
                label,
                loc,
                K::BadValue,
                format!(
                    "{state} must stay within ±π/2 rad (the Euler angles are singular there), found [{}, {}]",
                    validate::short(lo),
                    validate::short(hi)
                ),
            ));
        }
        bounds.push((state.clone(), lo, hi));
    }
    // The model's state order (the JSON object's order is not kept).
    bounds.sort_by_key(|(s, _, _)| states.iter().position(|n| n == s));
    Ok(DeclaredEnvelope { bounds })
}

/// The observed [min, max] of each state of [`margin_floor`] over every row of `logs`, in
/// [`STATE_COLUMNS`] order; `None` without rows.
pub fn observed(logs: &[&FlightLog]) -> Option<Vec<(String, f64, f64)>> {
    let mut out = Vec::new();
    for (i, name) in STATE_COLUMNS.iter().enumerate() {
        if margin_floor(name).is_none() {
            continue;
        }
        let values = logs
            .iter()
            .flat_map(|l| &l.segments)
            .flat_map(|s| s.x.iter().map(move |x| x[i]))
            .filter(|v| v.is_finite());
        let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if lo > hi {
            return None;
        }
        out.push((name.to_string(), lo, hi));
    }
    Some(out)
}

/// The envelope of observed ranges: each [min, max] widened by [`MARGIN_FACTOR`] times its
/// half-width plus the state's floor, roll and pitch capped at ±[`IDENTIFIED_TILT_CAP`] (or the
/// observed value, if larger, up to ±π/2), everything within ±[`ENVELOPE_MAX_ABS`]; rounded
/// outwards to 0.001.
pub fn widen(observed: &[(String, f64, f64)]) -> DeclaredEnvelope {
    let bounds = observed
        .iter()
        .map(|(name, min, max)| {
            let floor = margin_floor(name).unwrap_or(0.0);
            let margin = MARGIN_FACTOR * (max - min) / 2.0 + floor;
            let cap = if name == "roll" || name == "pitch" {
                IDENTIFIED_TILT_CAP.max(min.abs()).max(max.abs()).min(TILT_MAX_ABS)
            } else {
                ENVELOPE_MAX_ABS
            };
            // Outwards to 0.001 (a rounding error of 1e-9 does not move a bound by 0.001).
            let lo = ((min - margin) * 1e3 + 1e-6).floor() / 1e3;
            let hi = ((max + margin) * 1e3 - 1e-6).ceil() / 1e3;
            (name.clone(), lo.max(-cap), hi.min(cap))
        })
        .collect();
    DeclaredEnvelope { bounds }
}

/// The envelope `uavgen identify` writes for a model fitted on `logs`: [`widen`] of
/// [`observed`]. `None` without rows.
pub fn from_logs(logs: &[&FlightLog]) -> Option<DeclaredEnvelope> {
    observed(logs).map(|o| widen(&o))
}

/// `model_text` with `envelope` set to `envelope` (added at the end, or replacing the block the
/// file has); the result is validated as a model file.
pub fn attach(model_text: &str, label: &str, envelope: &DeclaredEnvelope) -> Result<String, ModelError> {
    let text = validate::strip_bom(model_text);
    let value: Value = serde_json::from_str(text).map_err(|e| super::load::json_syntax_error(text, label, &e))?;
    let Value::Object(mut map) = value else {
        return Err(ModelError::new(
            label,
            "",
            K::Json,
            "the top level must be a JSON object",
        ));
    };
    let base = if map.remove("envelope").is_some() {
        // Re-serialised without the old block (keys in serde_json's order).
        serde_json::to_string_pretty(&map).map_err(|e| ModelError::new(label, "", K::Json, e.to_string()))?
    } else {
        text.to_string()
    };
    let close = base
        .rfind('}')
        .ok_or_else(|| ModelError::new(label, "", K::Json, "the top level must be a JSON object"))?;
    let head = base[..close].trim_end();
    let sep = if map.is_empty() { "" } else { "," };
    let out = format!("{head}{sep}\n  \"envelope\": {}\n}}\n", envelope.to_json_text());
    super::load::parse(&out, label)?;
    Ok(out)
}

/// How many rows of `log` leave `envelope` (on the states a flight log has), and which states
/// they leave: `(rows outside, rows, states)`.
pub fn rows_outside(envelope: &DeclaredEnvelope, log: &FlightLog) -> (usize, usize, Vec<String>) {
    let columns: Vec<(usize, f64, f64, &str)> = envelope
        .bounds
        .iter()
        .filter_map(|(s, lo, hi)| {
            STATE_COLUMNS
                .iter()
                .position(|c| c == s)
                .map(|i| (i, *lo, *hi, s.as_str()))
        })
        .collect();
    let mut left = vec![false; columns.len()];
    let (mut outside, mut rows) = (0, 0);
    for x in log.segments.iter().flat_map(|s| &s.x) {
        rows += 1;
        let mut out = false;
        for (k, &(i, lo, hi, _)) in columns.iter().enumerate() {
            if !(x[i] >= lo && x[i] <= hi) {
                left[k] = true;
                out = true;
            }
        }
        outside += usize::from(out);
    }
    let states = columns
        .iter()
        .zip(left)
        .filter(|(_, l)| *l)
        .map(|(c, _)| c.3.to_string())
        .collect();
    (outside, rows, states)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn states() -> Vec<String> {
        crate::model::DEFAULT_STATES.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_range_is_widened_by_its_half_width_and_the_floor() {
        // vx observed in [-1, 3]: half-width 2, margin 2·2 + 0.5 = 4.5.
        let e = widen(&[
            ("vx".into(), -1.0, 3.0),
            ("roll".into(), -0.2, 0.2),
            ("pitch".into(), -1.4, 1.4),
        ]);
        assert_eq!(e.get("vx"), Some((-5.5, 7.5)));
        // roll: margin 2·0.2 + 0.1 = 0.5.
        assert_eq!(e.get("roll"), Some((-0.7, 0.7)));
        // pitch: 1.4 + 1.5 would pass π/2; capped at 1.5.
        assert_eq!(e.get("pitch"), Some((-1.5, 1.5)));
    }

    #[test]
    fn bad_blocks_name_the_field_and_the_value() {
        let s = states();
        let err = |v: Value| parse(&v, "m.json", &s).unwrap_err().to_string();
        assert_eq!(
            err(serde_json::json!({"vx": [2.0, 1.0]})),
            "m.json: envelope.vx: lo must be below hi, found [2, 1]"
        );
        assert!(err(serde_json::json!({"speed": [0, 1]})).starts_with("m.json: envelope.speed: 'speed' is not a state"));
        assert!(err(serde_json::json!({"vx": [0, 1e300]}))
            .contains("envelope.vx[1]: an envelope bound must be finite with magnitude at most 1000000, found 1e300"));
        assert!(err(serde_json::json!({"roll": [-2, 2]})).contains("envelope.roll: roll must stay within ±π/2"));
        assert!(err(serde_json::json!({"vx": [1]})).contains("envelope.vx: expected [lo, hi]"));
        assert!(err(serde_json::json!({"vx": ["a", 1]})).contains("envelope.vx[0]: expected a number"));
        assert!(err(serde_json::json!([1, 2])).contains("envelope: expected an object"));
        assert!(err(serde_json::json!({})).contains("envelope: an empty envelope"));
        let ok = parse(&serde_json::json!({"vz": [-1, 2], "roll": [-0.5, 0.5]}), "m.json", &s).unwrap();
        // In state order.
        assert_eq!(ok.bounds, vec![("roll".into(), -0.5, 0.5), ("vz".into(), -1.0, 2.0)]);
    }
}
