//! The optional `corrections` block of `uavgen-model/1`: unmodelled physical effects added to a
//! model of any kind (docs/model-format.md#corrections). This file holds the schema (serde), the
//! validation with located errors, the extra states the block adds and a summary for
//! `uavgen check`. The equations are built in `ir/corrections.rs`.
//!
//! With v = [vx vy vz] (world frame), v̇_base the base model's (vx, vy, vz) rows and
//! T = v̇_base + g e_z its thrust acceleration, the corrections add to v̇:
//!
//! ```text
//! linear_drag     −diag(xy, xy, z) v
//! quadratic_drag  −diag(xy, xy, z) √(‖v‖² + ε²) v          ε = 0.1 m/s
//! force_bias      b
//! thrust_gain     e_z · κ · T_z
//! thrust_decay    e_z · c · flight_time · T_z               extra state flight_time, d/dt = 1
//! ground_effect   e_z · gain · T_z · ρ²,  ρ² = (R/4)² / (z² + (R/4)²)
//! ```
//!
//! The thrust terms act on the vertical row only: behind an autopilot that holds the commanded
//! vertical speed, a thrust or mass mismatch shows in the vertical response, while the horizontal
//! acceleration at a given tilt returns to g·tan(tilt) once the vertical loop has compensated.
//!
//! `actuator_lag` adds a state `<input>_lagged` per listed input, d/dt = (u − s)/τ, which the
//! base model and the other corrections see instead of the input; `acceleration_lag` adds a state
//! `<state>_dot_lagged` per listed velocity or rate state, d/dt = (ẋ_base − ℓ)/τ, which replaces the
//! base model's row of that state (motor lag: the forces and torques follow the base model's with
//! a delay, state feedback of the autopilot included; thrust corrections see the lagged thrust);
//! `latency` is a pure input delay that is not part of f (the generated crate exports it, the
//! runtime compensates it).

use super::error::{ModelError, ModelErrorKind as K};
use super::file::DEFAULT_STATES;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// ε of the quadratic drag's smooth speed √(‖v‖² + ε²), in m/s.
pub const QUADRATIC_DRAG_EPSILON: f64 = 0.1;
/// g of the thrust corrections for model kinds without a gravity of their own (SINDy), in m/s².
pub const STANDARD_GRAVITY: f64 = 9.81;
/// The extra state of `thrust_decay`: time since the start of the flight, in s.
pub const FLIGHT_TIME: &str = "flight_time";
/// The extra state of an actuator lag on input `u` is named `u` + this suffix.
pub const LAGGED_SUFFIX: &str = "_lagged";
/// The extra state of an acceleration lag on state `x` is named `x` + this suffix.
pub const DOT_LAGGED_SUFFIX: &str = "_dot_lagged";
/// The states an acceleration lag may act on (the rows of the base model that are accelerations).
pub const LAGGABLE_STATES: [&str; 6] = ["vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"];

/// The `corrections` block as written. Every field is optional; unknown fields are rejected.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Corrections {
    /// Free text: what produced the block (e.g. `uavgen diagnose …`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    /// Δv̇ = −diag(xy, xy, z) v, in 1/s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear_drag: Option<Drag>,
    /// Δv̇ = −diag(xy, xy, z) √(‖v‖² + ε²) v, in 1/m.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quadratic_drag: Option<Drag>,
    /// Δv̇ = b, in m/s² (world frame).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_bias: Option<[f64; 3]>,
    /// Δv̇_z = κ (v̇_base,z + g), dimensionless.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thrust_gain: Option<f64>,
    /// Δv̇_z = c · flight_time · (v̇_base,z + g).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thrust_decay: Option<ThrustDecay>,
    /// Δv̇_z = gain · (v̇_base,z + g) · ρ².
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_effect: Option<GroundEffect>,
    /// Input name → first-order lag time constant τ in s.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub actuator_lag: BTreeMap<String, f64>,
    /// Velocity or rate state name (vx … yaw_rate) → first-order lag time constant τ in s of the
    /// base model's row of that state.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub acceleration_lag: BTreeMap<String, f64>,
    /// Input name → pure delay in s.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub latency: BTreeMap<String, f64>,
    /// Input name → gain k: the base model sees k times the (delayed, lagged) input — the
    /// aircraft answers a command more (k > 1) or less than the model.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub input_gain: BTreeMap<String, f64>,
    /// Attitude or yaw loop (its rate state: roll_rate, pitch_rate, yaw_rate) → the aircraft's
    /// loop against the base model's: row = gain · own + coupling · (base − own), where `own` is
    /// the base row with every variable outside the loop set to 0 ([`LOOPS`]).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub loop_mismatch: BTreeMap<String, LoopMismatch>,
}

/// The loops `loop_mismatch` may name: (rate state, the loop's own states, its own input by
/// position in the standard inputs u_vz u_roll u_pitch u_yaw_rate). Everything else the base row
/// reads is the loop's coupling to the other channels.
pub const LOOPS: [(&str, &[&str], usize); 3] = [
    ("roll_rate", &["roll", "roll_rate"], 1),
    ("pitch_rate", &["pitch", "pitch_rate"], 2),
    ("yaw_rate", &["yaw_rate"], 3),
];

/// How the aircraft's loop differs from the base model's (`loop_mismatch`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoopMismatch {
    /// Scale of the loop's own part (1: as the base model). A second-order attitude loop scaled by
    /// ρ has √ρ times the base model's bandwidth.
    pub gain: f64,
    /// Scale of the loop's coupling to the other channels (1: as the base model, 0: none).
    #[serde(default = "one")]
    pub coupling: f64,
}

fn one() -> f64 {
    1.0
}

/// Drag coefficients, horizontal (x and y alike, so the drag does not depend on the heading) and
/// vertical. A missing coefficient is 0.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Drag {
    #[serde(default)]
    pub xy: f64,
    #[serde(default)]
    pub z: f64,
}

/// Thrust that changes linearly with flight time (battery sag).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThrustDecay {
    /// c in 1/s: the relative thrust change per second of flight.
    pub per_second: f64,
}

/// Extra lift near the ground (a smooth, bounded form of Cheeseman-Bennett).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundEffect {
    /// Dimensionless gain (1 for the classic model).
    pub gain: f64,
    /// Rotor radius R in m.
    pub rotor_radius: f64,
}

impl Corrections {
    /// τ of the lag on `input`, if it has one.
    pub fn lag(&self, input: &str) -> Option<f64> {
        self.actuator_lag.get(input).copied()
    }

    /// τ of the acceleration lag on `state`, if it has one.
    pub fn acceleration_lag(&self, state: &str) -> Option<f64> {
        self.acceleration_lag.get(state).copied()
    }

    /// The gain on `input` (1 when it has none).
    pub fn gain(&self, input: &str) -> f64 {
        self.input_gain.get(input).copied().unwrap_or(1.0)
    }

    /// The pure delay of `input` in s (0 when it has none).
    pub fn delay(&self, input: &str) -> f64 {
        self.latency.get(input).copied().unwrap_or(0.0)
    }

    /// The states the block adds, in state order: `<input>_lagged` for each lagged input (in
    /// input order), `<state>_dot_lagged` for each acceleration lag (in state order), then
    /// `flight_time` if there is a thrust decay.
    pub fn extra_states(&self, inputs: &[String]) -> Vec<String> {
        let lagged = inputs
            .iter()
            .filter(|u| self.actuator_lag.contains_key(*u))
            .map(|u| format!("{u}{LAGGED_SUFFIX}"));
        let dot_lagged = LAGGABLE_STATES
            .iter()
            .filter(|x| self.acceleration_lag.contains_key(**x))
            .map(|x| format!("{x}{DOT_LAGGED_SUFFIX}"));
        lagged
            .chain(dot_lagged)
            .chain(self.thrust_decay.map(|_| FLIGHT_TIME.to_string()))
            .collect()
    }

    /// Check the block for a model with these (base) states and inputs; `label` names the file.
    /// Locations are JSON paths under `corrections`.
    pub fn validate(&self, label: &str, states: &[String], inputs: &[String]) -> Result<(), ModelError> {
        let bad = |loc: &str, message: String| {
            Err(ModelError::new(
                label,
                format!("corrections{loc}"),
                K::BadValue,
                message,
            ))
        };
        if states.iter().map(String::as_str).ne(DEFAULT_STATES) {
            return bad(
                "",
                format!(
                    "corrections need the 12 standard states in the standard order ({}), because the velocity \
                     and height rows are found by these names; this model's states are: {}",
                    DEFAULT_STATES.join(" "),
                    states.join(" ")
                ),
            );
        }
        for (field, drag) in [
            ("linear_drag", &self.linear_drag),
            ("quadratic_drag", &self.quadratic_drag),
        ] {
            for (axis, v) in drag.iter().flat_map(|d| [("xy", d.xy), ("z", d.z)]) {
                if !(v.is_finite() && v >= 0.0) {
                    return bad(
                        &format!(".{field}.{axis}"),
                        format!("must be finite and ≥ 0, found {v}"),
                    );
                }
            }
        }
        for (i, b) in self.force_bias.iter().flatten().enumerate() {
            if !b.is_finite() {
                return bad(&format!(".force_bias[{i}]"), format!("must be finite, found {b}"));
            }
        }
        if let Some(k) = self.thrust_gain {
            // 1 + κ = m_assumed / m_true > 0.
            if !(k.is_finite() && k > -1.0) {
                return bad(
                    ".thrust_gain",
                    format!("must be finite and > −1 (κ = m_assumed/m_true − 1), found {k}"),
                );
            }
        }
        if let Some(d) = self.thrust_decay {
            if !d.per_second.is_finite() {
                return bad(
                    ".thrust_decay.per_second",
                    format!("must be finite, found {}", d.per_second),
                );
            }
        }
        if let Some(e) = self.ground_effect {
            if !(e.gain.is_finite() && e.gain >= 0.0) {
                return bad(
                    ".ground_effect.gain",
                    format!("must be finite and ≥ 0, found {}", e.gain),
                );
            }
            if !(e.rotor_radius.is_finite() && e.rotor_radius > 0.0) {
                return bad(
                    ".ground_effect.rotor_radius",
                    format!("must be finite and > 0 (m), found {}", e.rotor_radius),
                );
            }
        }
        for (field, map, positive) in [
            ("actuator_lag", &self.actuator_lag, true),
            ("latency", &self.latency, false),
        ] {
            for (name, &v) in map {
                let loc = format!(".{field}.{name}");
                if !inputs.contains(name) {
                    return Err(ModelError::new(
                        label,
                        format!("corrections{loc}"),
                        K::UnknownVariable,
                        format!("'{name}' is not an input (inputs: {})", inputs.join(", ")),
                    ));
                }
                let (ok, what) = if positive {
                    (v.is_finite() && v > 0.0, "> 0 (a time constant in s)")
                } else {
                    (v.is_finite() && v >= 0.0, "≥ 0 (a delay in s)")
                };
                if !ok {
                    return bad(&loc, format!("must be finite and {what}, found {v}"));
                }
            }
        }
        for (name, &v) in &self.acceleration_lag {
            let loc = format!(".acceleration_lag.{name}");
            if !LAGGABLE_STATES.contains(&name.as_str()) {
                return Err(ModelError::new(
                    label,
                    format!("corrections{loc}"),
                    K::UnknownVariable,
                    format!(
                        "'{name}' is not a velocity or rate state (one of: {})",
                        LAGGABLE_STATES.join(", ")
                    ),
                ));
            }
            if !(v.is_finite() && v > 0.0) {
                return bad(
                    &loc,
                    format!("must be finite and > 0 (a time constant in s), found {v}"),
                );
            }
        }
        for (name, &k) in &self.input_gain {
            let loc = format!(".input_gain.{name}");
            if !inputs.contains(name) {
                return Err(ModelError::new(
                    label,
                    format!("corrections{loc}"),
                    K::UnknownVariable,
                    format!("'{name}' is not an input of the model (inputs: {})", inputs.join(", ")),
                ));
            }
            if !(k.is_finite() && k > 0.0 && k <= 10.0) {
                return bad(&loc, format!("must be in (0, 10], found {k}"));
            }
        }
        for (name, m) in &self.loop_mismatch {
            let loc = format!(".loop_mismatch.{name}");
            let Some(&(_, _, own_input)) = LOOPS.iter().find(|l| l.0 == name) else {
                let names: Vec<&str> = LOOPS.iter().map(|l| l.0).collect();
                return Err(ModelError::new(
                    label,
                    format!("corrections{loc}"),
                    K::UnknownVariable,
                    format!("'{name}' is not a loop's rate state (one of: {})", names.join(", ")),
                ));
            };
            if inputs.len() <= own_input {
                return bad(&loc, format!("the loop needs input {} of the model", own_input + 1));
            }
            if !(m.gain.is_finite() && m.gain > 0.0 && m.gain <= 100.0) {
                return bad(&format!("{loc}.gain"), format!("must be in (0, 100], found {}", m.gain));
            }
            if !(m.coupling.is_finite() && m.coupling.abs() <= 100.0) {
                return bad(
                    &format!("{loc}.coupling"),
                    format!("must be finite with |coupling| ≤ 100, found {}", m.coupling),
                );
            }
        }
        // The extra states must not take a name the model already uses (states are the standard
        // ones, so only an input can clash).
        for extra in self.extra_states(inputs) {
            if inputs.contains(&extra) {
                let loc = if let Some(x) = extra.strip_suffix(DOT_LAGGED_SUFFIX) {
                    format!(".acceleration_lag.{x}")
                } else if let Some(u) = extra.strip_suffix(LAGGED_SUFFIX) {
                    format!(".actuator_lag.{u}")
                } else {
                    ".thrust_decay".to_string()
                };
                return Err(ModelError::new(
                    label,
                    format!("corrections{loc}"),
                    K::Duplicate,
                    format!("the extra state '{extra}' would have the name of an input"),
                ));
            }
        }
        Ok(())
    }

    /// One line per effect, for `uavgen check`.
    pub fn summary(&self, inputs: &[String]) -> Vec<String> {
        let mut lines = Vec::new();
        let title = match &self.source {
            Some(s) => format!("corrections (source: {s}):"),
            None => "corrections:".to_string(),
        };
        lines.push(title);
        if let Some(d) = self.linear_drag {
            lines.push(format!("  linear drag: xy {} 1/s, z {} 1/s", d.xy, d.z));
        }
        if let Some(d) = self.quadratic_drag {
            lines.push(format!(
                "  quadratic drag: xy {} 1/m, z {} 1/m (ε = {QUADRATIC_DRAG_EPSILON} m/s)",
                d.xy, d.z
            ));
        }
        if let Some(b) = self.force_bias {
            lines.push(format!("  force bias: [{}, {}, {}] m/s²", b[0], b[1], b[2]));
        }
        if let Some(k) = self.thrust_gain {
            lines.push(format!("  thrust gain: κ = {k}"));
        }
        if let Some(d) = self.thrust_decay {
            lines.push(format!("  thrust decay: {} per second of flight_time", d.per_second));
        }
        if let Some(e) = self.ground_effect {
            lines.push(format!(
                "  ground effect: gain {}, rotor radius {} m",
                e.gain, e.rotor_radius
            ));
        }
        let per_input = |map: &BTreeMap<String, f64>| -> String {
            inputs
                .iter()
                .filter_map(|u| map.get(u).map(|v| format!("{u} {v} s")))
                .collect::<Vec<_>>()
                .join(", ")
        };
        if !self.actuator_lag.is_empty() {
            lines.push(format!("  actuator lag: {}", per_input(&self.actuator_lag)));
        }
        if !self.acceleration_lag.is_empty() {
            let per_state: Vec<String> = LAGGABLE_STATES
                .iter()
                .filter_map(|x| self.acceleration_lag.get(*x).map(|v| format!("{x} {v} s")))
                .collect();
            lines.push(format!("  acceleration lag: {}", per_state.join(", ")));
        }
        if !self.input_gain.is_empty() {
            lines.push(format!(
                "  input gain: {}",
                self.input_gain
                    .iter()
                    .map(|(u, k)| format!("{u} × {k}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        if !self.loop_mismatch.is_empty() {
            let per_loop: Vec<String> = LOOPS
                .iter()
                .filter_map(|l| {
                    self.loop_mismatch
                        .get(l.0)
                        .map(|m| format!("{} gain {} coupling {}", l.0, m.gain, m.coupling))
                })
                .collect();
            lines.push(format!("  loop mismatch: {}", per_loop.join(", ")));
        }
        if !self.latency.is_empty() {
            lines.push(format!(
                "  latency (not in f; INPUT_DELAY of the generated crate): {}",
                per_input(&self.latency)
            ));
        }
        let extra = self.extra_states(inputs);
        if !extra.is_empty() {
            lines.push(format!("  extra states: {}", extra.join(", ")));
        }
        if lines.len() == 1 {
            lines.push("  (empty)".to_string());
        }
        lines
    }
}

/// The text of a model file with `corrections` set (replaced if the file has one), validated as
/// `--model` would read it. A file without the block keeps its own formatting: the block is
/// inserted before the closing brace of the top-level object. `label` names the file in errors.
pub fn attach(model_text: &str, label: &str, corrections: &Corrections) -> Result<String, ModelError> {
    let value: serde_json::Value =
        serde_json::from_str(model_text).map_err(|e| super::load::json_syntax_error(model_text, label, &e))?;
    let block = serde_json::to_value(corrections).expect("corrections serialise");
    let text = match value {
        serde_json::Value::Object(mut map) if map.contains_key("corrections") => {
            map.insert("corrections".to_string(), block);
            serde_json::to_string_pretty(&map).expect("a JSON object serialises") + "\n"
        }
        serde_json::Value::Object(map) => {
            let close = model_text.rfind('}').expect("a JSON object ends with '}'");
            let head = model_text[..close].trim_end();
            let pretty = serde_json::to_string_pretty(&block).expect("corrections serialise");
            let indented = pretty.replace('\n', "\n  ");
            let sep = if map.is_empty() { "" } else { "," };
            format!("{head}{sep}\n  \"corrections\": {indented}\n}}\n")
        }
        _ => {
            return Err(ModelError::new(
                label,
                "",
                K::Json,
                "the top level must be a JSON object",
            ))
        }
    };
    // Values JSON cannot hold (NaN, ∞) were written as null: check the block itself too.
    let model = super::load::parse(&text, label)?;
    corrections.validate(label, model.base_states(), &model.inputs)?;
    Ok(text)
}
