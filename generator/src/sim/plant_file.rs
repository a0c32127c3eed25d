//! The `uavgen-plant/1` plant file: schema, parsing and validation (docs/plant-format.md).
//!
//! Parsing has three stages, like the model files (`model/load.rs`): the text becomes a JSON
//! value (syntax errors with line and column; a NaN, Infinity or overflowing number is
//! replaced by a marker so that the next stage can name its field), `format` is checked and
//! the value is deserialised into [`PlantFile`] (errors with the JSON path, unknown fields and
//! unknown effects rejected), then [`PlantFile::validate`] checks every range. No input panics.

use super::error::{PlantError, PlantErrorKind as K};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::path::Path;

/// The `format` tag this version reads and writes.
pub const PLANT_FORMAT: &str = "uavgen-plant/1";

/// The effect names, as keys of `effects` (docs/plant-format.md).
pub const EFFECT_NAMES: [&str; 10] = [
    "linear_drag",
    "quadratic_drag",
    "wind",
    "motor_lag",
    "latency",
    "payload",
    "battery_sag",
    "ground_effect",
    "sensor_noise",
    "sample_hold",
];

/// The paper's input bounds: |u_vz| ≤ 5 m/s, |u_roll|, |u_pitch| ≤ 0.611 rad, |u_yaw_rate| ≤ 5π/6 rad/s.
pub const PAPER_INPUT_LIMITS: [f64; 4] = [5.0, 0.611, 0.611, 5.0 * std::f64::consts::PI / 6.0];

/// The lowest allowed fine integration rate (sample rate × substeps), Hz.
pub const MIN_FINE_RATE_HZ: f64 = 200.0;

/// The highest sample rate accepted, Hz.
pub const MAX_RATE_HZ: f64 = 10_000.0;

/// The most RK4 substeps per sample accepted.
pub const MAX_SUBSTEPS: usize = 10_000;

/// A plant: vehicle, autopilot, integration and effects.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlantFile {
    /// Always [`PLANT_FORMAT`].
    pub format: String,
    pub name: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    pub vehicle: Vehicle,
    pub autopilot: Autopilot,
    pub integration: Integration,
    /// Every effect is off unless present.
    #[serde(default)]
    pub effects: Effects,
    /// Free-form notes (where the numbers come from); not interpreted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<Value>,
    /// The file (or label) the plant was read from; not part of the file.
    #[serde(skip)]
    pub source: String,
}

/// The rigid body.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vehicle {
    /// kg; also the mass the autopilot assumes (see the `payload` effect).
    pub mass: f64,
    /// Principal moments of inertia Ix, Iy, Iz in the body frame, kg m².
    pub inertia: [f64; 3],
    /// m/s².
    #[serde(default = "default_gravity")]
    pub gravity: f64,
    /// Largest total rotor thrust, N.
    pub max_thrust: f64,
    /// m (ground effect).
    pub rotor_radius: f64,
    /// Battery voltage when full, V (logged as `battery_voltage`; constant without `battery_sag`).
    pub battery_voltage: f64,
}

fn default_gravity() -> f64 {
    9.81
}

/// The emulated DJI-SDK autopilot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Autopilot {
    /// Vertical-velocity loop gain, 1/s: T = m (g + k_vz (u_vz − vz)) / (cos φ cos θ).
    pub k_vz: f64,
    /// Attitude stiffness per body axis (roll, pitch, yaw), 1/s².
    pub kp_att: [f64; 3],
    /// Body-rate damping per body axis, 1/s.
    pub kd_att: [f64; 3],
    /// Lead the yaw set-point by (kd_yaw / kp_yaw) u_yaw_rate (RotorPy's cmd_ctatt), so that the
    /// yaw rate follows u_yaw_rate without a steady lag.
    #[serde(default = "default_true")]
    pub yaw_rate_feedforward: bool,
    /// Commands are clamped to ±these: [u_vz m/s, u_roll rad, u_pitch rad, u_yaw_rate rad/s].
    #[serde(default = "default_limits")]
    pub input_limits: [f64; 4],
}

fn default_true() -> bool {
    true
}

fn default_limits() -> [f64; 4] {
    PAPER_INPUT_LIMITS
}

/// Sampling and integration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Integration {
    /// Sample (log and command) rate, Hz.
    pub rate_hz: f64,
    /// RK4 substeps per sample; rate_hz × substeps must be at least 200 Hz.
    pub substeps: usize,
}

/// The optional effects; each is off when absent.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Effects {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear_drag: Option<LinearDrag>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quadratic_drag: Option<QuadraticDrag>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wind: Option<Wind>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motor_lag: Option<MotorLag>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency: Option<Latency>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub payload: Option<Payload>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub battery_sag: Option<BatterySag>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ground_effect: Option<GroundEffect>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_noise: Option<SensorNoise>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sample_hold: Option<SampleHold>,
}

impl Effects {
    /// The names of the effects that are on, in [`EFFECT_NAMES`] order.
    pub fn active(&self) -> Vec<&'static str> {
        let on = [
            self.linear_drag.is_some(),
            self.quadratic_drag.is_some(),
            self.wind.is_some(),
            self.motor_lag.is_some(),
            self.latency.is_some(),
            self.payload.is_some(),
            self.battery_sag.is_some(),
            self.ground_effect.is_some(),
            self.sensor_noise.is_some(),
            self.sample_hold.is_some(),
        ];
        EFFECT_NAMES
            .iter()
            .zip(on)
            .filter(|(_, on)| *on)
            .map(|(n, _)| *n)
            .collect()
    }
}

/// Rotor drag: F_body = −m diag(d) v_air,body (d per body axis, 1/s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinearDrag {
    pub coefficients: [f64; 3],
}

/// Parasitic drag: F_body = −m |v_air| diag(c) v_air,body (c per body axis, 1/m).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct QuadraticDrag {
    pub coefficients: [f64; 3],
}

/// Wind: steady plus Dryden turbulence; acts through the drag effects (on airspeed) and through
/// an optional direct force m diag(direct_coefficient) w.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wind {
    /// Steady wind, inertial ENU, m/s.
    #[serde(default)]
    pub velocity: [f64; 3],
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub turbulence: Option<Turbulence>,
    /// Force per mass per wind speed, inertial axes, 1/s (independent of the vehicle's velocity).
    #[serde(default)]
    pub direct_coefficient: [f64; 3],
}

/// Dryden turbulence (first-order form per axis).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Turbulence {
    /// Standard deviation per inertial axis, m/s.
    pub sigma: [f64; 3],
    /// Turbulence length scale L, m (correlation time L / V).
    pub length_scale: f64,
}

/// First-order lag on thrust and torques.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorLag {
    /// s.
    pub time_constant: f64,
}

/// Command delay: `delay` for all four inputs, or `per_channel` [u_vz, u_roll, u_pitch, u_yaw_rate].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Latency {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delay: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub per_channel: Option<[f64; 4]>,
}

impl Latency {
    /// The delay of each channel, s.
    pub fn delays(&self) -> [f64; 4] {
        match (self.per_channel, self.delay) {
            (Some(d), _) => d,
            (None, Some(d)) => [d; 4],
            (None, None) => [0.0; 4],
        }
    }
}

/// Extra mass the autopilot does not know about.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Payload {
    /// kg (negative: lighter than the autopilot assumes).
    pub mass: f64,
}

/// Battery voltage V(t) = max(V0 − rate t, min_voltage); thrust and torques per command scale by
/// (V/V0)^exponent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BatterySag {
    /// V/s.
    pub rate: f64,
    /// V; default 0.8 V0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_voltage: Option<f64>,
    #[serde(default = "default_exponent")]
    pub exponent: f64,
}

fn default_exponent() -> f64 {
    2.0
}

/// Cheeseman-Bennett ground effect T_ige / T_oge = 1 / (1 − (R / 4h)²), capped.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundEffect {
    /// m; default `vehicle.rotor_radius`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotor_radius: Option<f64>,
    /// Cap of the thrust ratio (≥ 1).
    #[serde(default = "default_max_ratio")]
    pub max_ratio: f64,
    /// Height of the rotor plane above the logged z, m (h = z + rotor_height).
    #[serde(default)]
    pub rotor_height: f64,
}

fn default_max_ratio() -> f64 {
    1.5
}

/// White Gaussian noise on the logged (measured) values, standard deviations.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorNoise {
    /// x, y, z, m.
    #[serde(default)]
    pub pos: f64,
    /// vx, vy, vz, m/s.
    #[serde(default)]
    pub vel: f64,
    /// roll, pitch, yaw, rad.
    #[serde(default)]
    pub att: f64,
    /// Euler-angle rates, rad/s.
    #[serde(default)]
    pub rate: f64,
    /// battery_voltage, V.
    #[serde(default)]
    pub volt: f64,
}

/// Stale telemetry: a logged row repeats the previous row's states with this probability.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SampleHold {
    pub probability: f64,
    /// At most this many consecutive repeats (the M100 logs: 1); none: unlimited.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_run: Option<usize>,
}

impl PlantFile {
    /// Read and validate a plant file; errors name the file as `path` displays.
    pub fn load(path: &Path) -> Result<PlantFile, PlantError> {
        let label = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|e| PlantError::new(&label, "", K::Io, format!("cannot read: {e}")))?;
        let text = String::from_utf8(bytes).map_err(|_| PlantError::new(&label, "", K::Json, "not UTF-8 text"))?;
        Self::parse(&text, &label)
    }

    /// Validate plant-file text; `source` names the file in errors and in [`PlantFile::source`].
    pub fn parse(text: &str, source: &str) -> Result<PlantFile, PlantError> {
        let value = json_value(crate::validate::strip_bom(text), source)?;
        let obj = value
            .as_object()
            .ok_or_else(|| PlantError::new(source, "", K::Json, "the top level must be a JSON object"))?;
        match obj.get("format") {
            None => {
                return Err(PlantError::new(
                    source,
                    "format",
                    K::MissingField,
                    format!("missing field `format` (\"{PLANT_FORMAT}\")"),
                ))
            }
            Some(Value::String(f)) if f == PLANT_FORMAT => {}
            Some(Value::String(f)) if f == NON_FINITE_MARK => {
                return Err(typed_error(source, "format".into(), NON_FINITE_MARK.into()))
            }
            Some(other) => {
                return Err(PlantError::new(
                    source,
                    "format",
                    K::UnknownFormat,
                    format!("unknown format {other}: this uavgen reads \"{PLANT_FORMAT}\""),
                ))
            }
        }
        let mut file: PlantFile = serde_path_to_error::deserialize(value).map_err(|e| {
            let path = e.path().to_string();
            let path = if path == "." { String::new() } else { path };
            let inner = e.into_inner().to_string();
            typed_error(source, path, inner)
        })?;
        file.source = source.to_owned();
        file.validate()?;
        Ok(file)
    }

    /// Check every value's range and the consistency of the effects. [`PlantFile::parse`] calls
    /// it; call it again after changing a file in code.
    pub fn validate(&self) -> Result<(), PlantError> {
        let v = Validator { file: &self.source };
        if self.format != PLANT_FORMAT {
            return Err(PlantError::new(
                &self.source,
                "format",
                K::UnknownFormat,
                format!("unknown format \"{}\": expected \"{PLANT_FORMAT}\"", self.format),
            ));
        }
        if self.name.trim().is_empty() {
            return Err(v.range("name", "the name must not be empty"));
        }
        let ve = &self.vehicle;
        v.positive("vehicle.mass", ve.mass)?;
        v.within("vehicle.mass", ve.mass, crate::validate::MASS_KG, "kg")?;
        v.within("vehicle.gravity", ve.gravity, crate::validate::GRAVITY, "m/s²")?;
        for (i, x) in ve.inertia.iter().enumerate() {
            v.positive(&format!("vehicle.inertia[{i}]"), *x)?;
        }
        v.positive("vehicle.gravity", ve.gravity)?;
        v.positive("vehicle.max_thrust", ve.max_thrust)?;
        v.positive("vehicle.rotor_radius", ve.rotor_radius)?;
        v.positive("vehicle.battery_voltage", ve.battery_voltage)?;
        if ve.max_thrust <= ve.mass * ve.gravity {
            return Err(v.range(
                "vehicle.max_thrust",
                format!(
                    "max_thrust {} N cannot lift the vehicle's weight m g = {:.3} N",
                    ve.max_thrust,
                    ve.mass * ve.gravity
                ),
            ));
        }
        let ap = &self.autopilot;
        v.positive("autopilot.k_vz", ap.k_vz)?;
        for i in 0..3 {
            v.positive(&format!("autopilot.kp_att[{i}]"), ap.kp_att[i])?;
            v.non_negative(&format!("autopilot.kd_att[{i}]"), ap.kd_att[i])?;
        }
        for (i, x) in ap.input_limits.iter().enumerate() {
            v.positive(&format!("autopilot.input_limits[{i}]"), *x)?;
        }
        for i in 1..3 {
            if ap.input_limits[i] >= std::f64::consts::FRAC_PI_2 {
                return Err(v.range(
                    &format!("autopilot.input_limits[{i}]"),
                    format!("a tilt limit must be below π/2, found {}", ap.input_limits[i]),
                ));
            }
        }
        let int = &self.integration;
        v.positive("integration.rate_hz", int.rate_hz)?;
        if int.rate_hz > MAX_RATE_HZ {
            return Err(v.range(
                "integration.rate_hz",
                format!("{} Hz is above the {MAX_RATE_HZ} Hz allowed", int.rate_hz),
            ));
        }
        if !(1..=MAX_SUBSTEPS).contains(&int.substeps) {
            return Err(v.range(
                "integration.substeps",
                format!("{} substeps per sample: 1 to {MAX_SUBSTEPS} are allowed", int.substeps),
            ));
        }
        let fine = int.rate_hz * int.substeps as f64;
        if fine < MIN_FINE_RATE_HZ {
            return Err(v.range(
                "integration.substeps",
                format!(
                    "rate_hz × substeps = {fine} Hz: the RK4 integration must run at {MIN_FINE_RATE_HZ} Hz or more"
                ),
            ));
        }
        let h = 1.0 / fine;
        self.validate_effects(&v, h)
    }

    fn validate_effects(&self, v: &Validator, h: f64) -> Result<(), PlantError> {
        let e = &self.effects;
        if let Some(d) = &e.linear_drag {
            for (i, c) in d.coefficients.iter().enumerate() {
                v.non_negative(&format!("effects.linear_drag.coefficients[{i}]"), *c)?;
            }
        }
        if let Some(d) = &e.quadratic_drag {
            for (i, c) in d.coefficients.iter().enumerate() {
                v.non_negative(&format!("effects.quadratic_drag.coefficients[{i}]"), *c)?;
            }
        }
        if let Some(w) = &e.wind {
            for i in 0..3 {
                v.finite(&format!("effects.wind.velocity[{i}]"), w.velocity[i])?;
                v.non_negative(
                    &format!("effects.wind.direct_coefficient[{i}]"),
                    w.direct_coefficient[i],
                )?;
            }
            if let Some(t) = &w.turbulence {
                for (i, s) in t.sigma.iter().enumerate() {
                    v.non_negative(&format!("effects.wind.turbulence.sigma[{i}]"), *s)?;
                }
                v.positive("effects.wind.turbulence.length_scale", t.length_scale)?;
            }
            let acts =
                e.linear_drag.is_some() || e.quadratic_drag.is_some() || w.direct_coefficient.iter().any(|c| *c > 0.0);
            if !acts {
                return Err(PlantError::new(
                    v.file,
                    "effects.wind",
                    K::Inconsistent,
                    "the wind has no effect: it acts through linear_drag or quadratic_drag (on airspeed) \
                     or through a non-zero direct_coefficient; enable one of them",
                ));
            }
        }
        if let Some(m) = &e.motor_lag {
            v.positive("effects.motor_lag.time_constant", m.time_constant)?;
            if m.time_constant < h {
                return Err(v.range(
                    "effects.motor_lag.time_constant",
                    format!(
                        "{} s is shorter than the RK4 step {h:.6} s: raise integration.substeps (or drop the effect)",
                        m.time_constant
                    ),
                ));
            }
        }
        if let Some(l) = &e.latency {
            match (l.delay, l.per_channel) {
                (Some(_), Some(_)) => {
                    return Err(PlantError::new(
                        v.file,
                        "effects.latency",
                        K::Inconsistent,
                        "give either `delay` (all inputs) or `per_channel`, not both",
                    ))
                }
                (None, None) => {
                    return Err(PlantError::new(
                        v.file,
                        "effects.latency.delay",
                        K::MissingField,
                        "missing field `delay` (s; or `per_channel`: [u_vz, u_roll, u_pitch, u_yaw_rate])",
                    ))
                }
                (Some(d), None) => v.delay("effects.latency.delay", d)?,
                (None, Some(ds)) => {
                    for (i, d) in ds.iter().enumerate() {
                        v.delay(&format!("effects.latency.per_channel[{i}]"), *d)?;
                    }
                }
            }
        }
        if let Some(p) = &e.payload {
            v.finite("effects.payload.mass", p.mass)?;
            let total = self.vehicle.mass + p.mass;
            if total <= 0.0 {
                return Err(v.range(
                    "effects.payload.mass",
                    format!("the true mass vehicle.mass + payload = {total} kg must be positive"),
                ));
            }
        }
        if let Some(b) = &e.battery_sag {
            v.non_negative("effects.battery_sag.rate", b.rate)?;
            v.non_negative("effects.battery_sag.exponent", b.exponent)?;
            if let Some(min) = b.min_voltage {
                v.positive("effects.battery_sag.min_voltage", min)?;
                if min > self.vehicle.battery_voltage {
                    return Err(v.range(
                        "effects.battery_sag.min_voltage",
                        format!(
                            "{min} V is above the full voltage vehicle.battery_voltage = {} V",
                            self.vehicle.battery_voltage
                        ),
                    ));
                }
            }
        }
        if let Some(g) = &e.ground_effect {
            if let Some(r) = g.rotor_radius {
                v.positive("effects.ground_effect.rotor_radius", r)?;
            }
            v.finite("effects.ground_effect.max_ratio", g.max_ratio)?;
            if g.max_ratio < 1.0 {
                return Err(v.range(
                    "effects.ground_effect.max_ratio",
                    format!("the thrust ratio cap must be at least 1, found {}", g.max_ratio),
                ));
            }
            v.non_negative("effects.ground_effect.rotor_height", g.rotor_height)?;
        }
        if let Some(n) = &e.sensor_noise {
            // Standard deviations a sensor can have; beyond them the log is noise.
            for (name, s, max, unit) in [
                ("pos", n.pos, 100.0, "m"),
                ("vel", n.vel, 100.0, "m/s"),
                ("att", n.att, std::f64::consts::PI, "rad"),
                ("rate", n.rate, 100.0, "rad/s"),
                ("volt", n.volt, 100.0, "V"),
            ] {
                v.within(&format!("effects.sensor_noise.{name}"), s, (0.0, max), unit)?;
            }
        }
        if let Some(s) = &e.sample_hold {
            v.finite("effects.sample_hold.probability", s.probability)?;
            if !(0.0..=1.0).contains(&s.probability) {
                return Err(v.range(
                    "effects.sample_hold.probability",
                    format!("a probability must be in [0, 1], found {}", s.probability),
                ));
            }
            if s.max_run == Some(0) {
                return Err(v.range("effects.sample_hold.max_run", "max_run must be at least 1"));
            }
        }
        Ok(())
    }

    /// The fine RK4 step, s.
    pub fn fine_step(&self) -> f64 {
        1.0 / (self.integration.rate_hz * self.integration.substeps.max(1) as f64)
    }

    /// The file as pretty-printed JSON with a trailing newline.
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(self).expect("a PlantFile serialises");
        s.push('\n');
        s
    }
}

struct Validator<'a> {
    file: &'a str,
}

impl Validator<'_> {
    fn range(&self, field: &str, message: impl Into<String>) -> PlantError {
        PlantError::new(self.file, field, K::OutOfRange, message)
    }

    /// Finite and within ±[`crate::validate::PLANT_MAX_ABS`] (every number of a plant file).
    fn finite(&self, field: &str, x: f64) -> Result<(), PlantError> {
        if !x.is_finite() {
            Err(PlantError::new(
                self.file,
                field,
                K::NonFinite,
                format!("non-finite value {x}: every number must be finite"),
            ))
        } else if x.abs() > crate::validate::PLANT_MAX_ABS {
            Err(self.range(
                field,
                format!(
                    "{} is out of range: every number of a plant file must be within ±{} (docs/plant-format.md)",
                    crate::validate::short(x),
                    crate::validate::short(crate::validate::PLANT_MAX_ABS)
                ),
            ))
        } else {
            Ok(())
        }
    }

    /// Within `range` (and finite).
    fn within(&self, field: &str, x: f64, range: (f64, f64), unit: &str) -> Result<(), PlantError> {
        self.finite(field, x)?;
        crate::validate::within(x, range, unit)
            .map(|_| ())
            .map_err(|m| self.range(field, m))
    }

    fn positive(&self, field: &str, x: f64) -> Result<(), PlantError> {
        self.finite(field, x)?;
        if x > 0.0 {
            Ok(())
        } else {
            Err(self.range(field, format!("must be positive, found {x}")))
        }
    }

    fn non_negative(&self, field: &str, x: f64) -> Result<(), PlantError> {
        self.finite(field, x)?;
        if x >= 0.0 {
            Ok(())
        } else {
            Err(self.range(field, format!("must not be negative, found {x}")))
        }
    }

    fn delay(&self, field: &str, x: f64) -> Result<(), PlantError> {
        self.non_negative(field, x)?;
        if x <= MAX_DELAY_S {
            Ok(())
        } else {
            Err(self.range(
                field,
                format!("a command delay of {x} s is beyond the {MAX_DELAY_S} s allowed"),
            ))
        }
    }
}

/// The longest command delay accepted, s.
pub const MAX_DELAY_S: f64 = 10.0;

/// Marks a non-finite number in the JSON text so that deserialisation can name its field.
const NON_FINITE_MARK: &str = "@@uavgen-non-finite@@";

/// Text → JSON value. NaN, Infinity and numbers that overflow f64 are replaced by a marker string.
fn json_value(text: &str, file: &str) -> Result<Value, PlantError> {
    let mut text = text.to_owned();
    // Each pass replaces one token; the bound only guards against a pathological file.
    for _ in 0..10_000 {
        let e = match serde_json::from_str::<Value>(&text) {
            Ok(v) => return Ok(v),
            Err(e) => e,
        };
        let at = format!("line {}, column {}", e.line(), e.column());
        match non_finite_token(&text, e.line(), e.column()) {
            Some(range) => text.replace_range(range, &format!("\"{NON_FINITE_MARK}\"")),
            None => {
                let msg = e.to_string();
                let msg = msg.split(" at line ").next().unwrap_or(&msg).to_owned();
                return Err(PlantError::new(file, at, K::Json, format!("invalid JSON: {msg}")));
            }
        }
    }
    Err(PlantError::new(
        file,
        "",
        K::Json,
        "invalid JSON: too many non-finite numbers",
    ))
}

/// The byte range of a NaN/Infinity/overflowing number token at (or just before) the 1-based
/// line and column of a JSON error.
fn non_finite_token(text: &str, line: usize, column: usize) -> Option<std::ops::Range<usize>> {
    let start_of_line: usize = text
        .split_inclusive('\n')
        .take(line.saturating_sub(1))
        .map(str::len)
        .sum();
    let line_text = text.get(start_of_line..)?.split('\n').next()?;
    let mut pos = start_of_line + column.saturating_sub(1).min(line_text.len());
    let bytes = text.as_bytes();
    let is_tok = |b: u8| b.is_ascii_alphanumeric() || b == b'.' || b == b'+' || b == b'-';
    // The column may point at the token or one past its end.
    if pos >= bytes.len() || !is_tok(bytes[pos]) {
        pos = pos.checked_sub(1)?;
    }
    if !is_tok(*bytes.get(pos)?) {
        return None;
    }
    let mut a = pos;
    while a > 0 && is_tok(bytes[a - 1]) {
        a -= 1;
    }
    let mut b = pos + 1;
    while b < bytes.len() && is_tok(bytes[b]) {
        b += 1;
    }
    let token = text.get(a..b)?;
    let bare = token.trim_start_matches(['-', '+']);
    let named = ["NaN", "nan", "Infinity", "infinity", "inf", "Inf"].contains(&bare);
    let overflow = token.parse::<f64>().is_ok_and(|x| x.is_infinite());
    (named || overflow).then_some(a..b)
}

fn typed_error(file: &str, path: String, inner: String) -> PlantError {
    if inner.contains(NON_FINITE_MARK) {
        return PlantError::new(
            file,
            path,
            K::NonFinite,
            "non-finite number (NaN or infinite): every number in a plant file must be finite",
        );
    }
    if inner.starts_with("missing field") {
        return PlantError::new(file, path, K::MissingField, inner);
    }
    if inner.starts_with("unknown field") {
        let name = inner.split('`').nth(1).unwrap_or("?");
        if path == "effects" || path == format!("effects.{name}") {
            return PlantError::new(
                file,
                format!("effects.{name}"),
                K::UnknownEffect,
                format!("unknown effect `{name}`: expected one of {}", EFFECT_NAMES.join(", ")),
            );
        }
        return PlantError::new(file, path, K::UnknownField, inner);
    }
    PlantError::new(file, path, K::BadType, inner)
}

/// A minimal valid plant file for unit tests.
#[cfg(test)]
pub(crate) mod tests_support {
    pub const NOMINAL: &str = r#"{
      "format": "uavgen-plant/1",
      "name": "t",
      "vehicle": { "mass": 2.9, "inertia": [0.05, 0.05, 0.085], "max_thrust": 60.9,
                   "rotor_radius": 0.1651, "battery_voltage": 24.6 },
      "autopilot": { "k_vz": 2.5, "kp_att": [144, 144, 6], "kd_att": [19.2, 19.2, 4.9] },
      "integration": { "rate_hz": 30, "substeps": 7 }
    }"#;
}

#[cfg(test)]
mod tests {
    use super::tests_support::NOMINAL;
    use super::*;

    fn with(field: &str, value: &str) -> String {
        NOMINAL.replacen(field, value, 1)
    }

    #[test]
    fn nominal_parses_with_defaults() {
        let p = PlantFile::parse(NOMINAL, "n.json").unwrap();
        assert_eq!(p.vehicle.gravity, 9.81);
        assert_eq!(p.autopilot.input_limits, PAPER_INPUT_LIMITS);
        assert!(p.effects.active().is_empty());
        assert_eq!(p.source, "n.json");
        // Round trip through to_json.
        let again = PlantFile::parse(&p.to_json(), "n.json").unwrap();
        assert_eq!(again, p);
    }

    #[test]
    fn errors_name_the_field() {
        let cases: Vec<(String, &str, K)> = vec![
            (with("\"mass\": 2.9", "\"mass\": -1"), "vehicle.mass", K::OutOfRange),
            (with("\"mass\": 2.9", "\"mass\": NaN"), "vehicle.mass", K::NonFinite),
            (with("\"max_thrust\": 60.9", "\"max_thrust\": -Infinity"), "vehicle.max_thrust", K::NonFinite),
            (with("\"max_thrust\": 60.9", "\"max_thrust\": 1e999"), "vehicle.max_thrust", K::NonFinite),
            (with("\"k_vz\": 2.5", "\"k_vz\": 2.5, \"gain\": 1"), "autopilot.gain", K::UnknownField),
            (with("\"rate_hz\": 30", "\"rate_hz\": 0"), "integration.rate_hz", K::OutOfRange),
            (with("\"substeps\": 7", "\"substeps\": 2"), "integration.substeps", K::OutOfRange),
            (with("\"substeps\": 7", "\"substeps\": -7"), "integration.substeps", K::BadType),
            (with("\"k_vz\": 2.5", "\"k_vz\": \"fast\""), "autopilot.k_vz", K::BadType),
            (with("\"kd_att\": [19.2, 19.2, 4.9]", "\"kd_att\": [19.2, 19.2]"), "autopilot.kd_att", K::BadType),
            (with("\"name\": \"t\",", ""), "", K::MissingField),
            (with("uavgen-plant/1", "uavgen-plant/2"), "format", K::UnknownFormat),
            (
                with("\"substeps\": 7 }", "\"substeps\": 7 }, \"effects\": { \"drag\": {} }"),
                "effects.drag",
                K::UnknownEffect,
            ),
            (
                with("\"substeps\": 7 }", "\"substeps\": 7 }, \"effects\": { \"sample_hold\": { \"probability\": 1.5 } }"),
                "effects.sample_hold.probability",
                K::OutOfRange,
            ),
            (
                with("\"substeps\": 7 }", "\"substeps\": 7 }, \"effects\": { \"latency\": { \"delay\": 0.1, \"per_channel\": [0,0,0,0] } }"),
                "effects.latency",
                K::Inconsistent,
            ),
            (
                with("\"substeps\": 7 }", "\"substeps\": 7 }, \"effects\": { \"wind\": { \"velocity\": [3, 0, 0] } }"),
                "effects.wind",
                K::Inconsistent,
            ),
            (
                with("\"substeps\": 7 }", "\"substeps\": 7 }, \"effects\": { \"motor_lag\": { \"time_constant\": 0.001 } }"),
                "effects.motor_lag.time_constant",
                K::OutOfRange,
            ),
            (
                with("\"substeps\": 7 }", "\"substeps\": 7 }, \"effects\": { \"payload\": { \"mass\": -3 } }"),
                "effects.payload.mass",
                K::OutOfRange,
            ),
            (
                with("\"substeps\": 7 }", "\"substeps\": 7 }, \"effects\": { \"linear_drag\": { \"coefficients\": [0.3, 0.3, 0.5], \"x\": 1 } }"),
                "effects.linear_drag.x",
                K::UnknownField,
            ),
        ];
        for (text, field, kind) in cases {
            let e = PlantFile::parse(&text, "p.json").expect_err(field);
            assert_eq!((e.field.as_str(), &e.kind), (field, &kind), "{e}");
            assert!(e.to_string().starts_with("p.json: "), "{e}");
        }
    }

    proptest::proptest! {
        /// Any edit of a valid file gives a plant or an error, never a panic.
        #[test]
        fn mangled_files_never_panic(at in 0usize..600, len in 0usize..12, junk in "[0-9a-zA-Z.,:{}\\[\\]\" eE+-]{0,12}") {
            let text = NOMINAL;
            let at = at.min(text.len());
            let end = (at + len).min(text.len());
            if text.is_char_boundary(at) && text.is_char_boundary(end) {
                let mangled = format!("{}{}{}", &text[..at], junk, &text[end..]);
                let _ = PlantFile::parse(&mangled, "p.json");
            }
        }
    }

    #[test]
    fn syntax_errors_have_a_line_and_garbage_never_panics() {
        let e = PlantFile::parse("{\n \"format\": ,\n}", "p.json").unwrap_err();
        assert_eq!(e.kind, K::Json);
        assert!(e.field.starts_with("line 2"), "{e}");
        for text in [
            "",
            "[]",
            "nan",
            "-",
            "{\"format\": NaN}",
            "\"x\"",
            "{\"a\": -Infinity",
            "1e999",
            "{{",
        ] {
            assert!(PlantFile::parse(text, "p.json").is_err(), "{text}");
        }
    }
}
