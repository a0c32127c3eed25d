//! Import profiles: which topic and field of a recording feeds each state and input of the log
//! contract, in which frame (docs/import.md, "Profiles"). A profile is a JSON file
//! (`uavgen-import-profile/1`); the built-in presets (`px4`, `mavros`, `dji-osdk-ros`,
//! `ardupilot`) are such files, compiled in from `generator/src/import/presets/`, and
//! `uavgen import --print-profile NAME` prints them as a starting point for one's own.

use super::error::{ImportError, ImportErrorKind};
use super::frames::{Body, Inertial};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The `format` value of a profile file.
pub const PROFILE_FORMAT: &str = "uavgen-import-profile/1";

/// The built-in presets: name and JSON text.
pub const PRESETS: [(&str, &str); 5] = [
    ("px4", include_str!("presets/px4.json")),
    ("mavros", include_str!("presets/mavros.json")),
    ("dji-osdk-ros", include_str!("presets/dji-osdk-ros.json")),
    ("ardupilot", include_str!("presets/ardupilot.json")),
    // The template for a delimited log of another schema (a motion-capture CSV): edit its column
    // names, units and frames (docs/import.md, "CSV of another schema").
    ("csv", include_str!("presets/csv.json")),
];

/// The one topic of a CSV recording: its columns are the topic's fields.
pub const CSV_TOPIC: &str = "csv";

/// A mapping from a recording to the 12 states and 4 inputs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// Always [`PROFILE_FORMAT`].
    pub format: String,
    pub name: String,
    /// Free text: the flight stack, which setpoint feeds which input, caveats.
    #[serde(default)]
    pub description: String,
    /// Time stamps of ROS messages: `header` (the message's `header.stamp`, when it has one) or
    /// `receive` (the recorder's log time). ULog and DataFlash have one clock.
    #[serde(default)]
    pub clock: Clock,
    /// x, y, z.
    pub position: Vector,
    /// vx, vy, vz (inertial; a body-frame velocity is rotated by the attitude).
    pub velocity: Vector,
    pub attitude: Attitude,
    /// roll_rate, pitch_rate, yaw_rate: body rates (converted to Euler-angle rates) or Euler-angle
    /// rates as logged.
    pub rates: Rates,
    pub inputs: Inputs,
    /// Optional battery voltage in V.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub battery_voltage: Option<Scalar>,
    /// CSV recordings only (and required there): the time column and its unit. A profile with
    /// `time` maps a delimited log of another schema; one without reads CSVs as the contract.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<TimeColumn>,
}

/// The time column of a CSV recording.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeColumn {
    pub field: String,
    pub unit: TimeUnit,
}

/// Units of a time column.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TimeUnit {
    S,
    Ms,
    Us,
    Ns,
}

impl TimeUnit {
    /// Seconds per unit.
    pub fn seconds(self) -> f64 {
        match self {
            TimeUnit::S => 1.0,
            TimeUnit::Ms => 1e-3,
            TimeUnit::Us => 1e-6,
            TimeUnit::Ns => 1e-9,
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Clock {
    #[default]
    Header,
    Receive,
}

/// The frame a vector is logged in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum VectorFrame {
    Enu,
    Ned,
    /// Body FLU: rotated into ENU by the attitude (velocity only).
    Flu,
    /// Body FRD: rotated into ENU by the attitude (velocity only).
    Frd,
}

/// Three fields of one topic.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Vector {
    pub topic: String,
    pub fields: [String; 3],
    pub frame: VectorFrame,
    /// Multiply by this first (1 for m and m/s; 0.001 for mm and mm/s).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub scale: f64,
}

/// The attitude: a quaternion `[w, x, y, z]` (body → inertial) or ZYX Euler angles
/// `[roll, pitch, yaw]`, in the given inertial and body frames.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Attitude {
    pub topic: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quaternion: Option<[String; 4]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub euler: Option<[String; 3]>,
    pub inertial: Inertial,
    pub body: Body,
    /// Multiply Euler angles by this first (1 for rad; 0.017453292519943295 for degrees, and
    /// 0.0017453292519943296 for ArduPilot's centidegrees).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub scale: f64,
    /// Euler angles logged with the opposite sign of the `inertial`/`body` convention (e.g.
    /// `["pitch"]` for a nose-up pitch in ENU/FLU, where pitch is positive nose down): negated first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub negate: Vec<Angle>,
}

/// How the rates are logged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RatesKind {
    /// Body angular rates (gyro, p q r) in the body frame of `body`: converted to Euler-angle rates
    /// with the attitude.
    Body,
    /// Already the time derivatives of the ENU/FLU Euler angles.
    Euler,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rates {
    pub topic: String,
    pub fields: [String; 3],
    pub kind: RatesKind,
    /// The body frame of body rates (ignored for Euler rates).
    pub body: Body,
    /// Multiply by this first (1 for rad/s; 0.017453292519943295 for deg/s).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub scale: f64,
    /// Euler-angle rates logged with the opposite sign (with a nose-up pitch: `["pitch"]`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub negate: Vec<Angle>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    pub u_vz: Input,
    pub u_roll: Input,
    pub u_pitch: Input,
    pub u_yaw_rate: Input,
}

impl Inputs {
    pub fn all(&self) -> [(&'static str, &Input); 4] {
        [
            ("u_vz", &self.u_vz),
            ("u_roll", &self.u_roll),
            ("u_pitch", &self.u_pitch),
            ("u_yaw_rate", &self.u_yaw_rate),
        ]
    }
}

/// One field, scaled: value = scale · field + offset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scalar {
    pub topic: String,
    pub field: String,
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub scale: f64,
    #[serde(default, skip_serializing_if = "is_zero")]
    pub offset: f64,
}

/// Which ZYX Euler angle of an attitude setpoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Angle {
    Roll,
    Pitch,
    Yaw,
}

impl Angle {
    pub fn index(self) -> usize {
        match self {
            Angle::Roll => 0,
            Angle::Pitch => 1,
            Angle::Yaw => 2,
        }
    }
}

/// An input: a scaled field, or one ENU/FLU Euler angle of an attitude setpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Input {
    pub topic: String,
    /// A scalar field (value = scale · field + offset) ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// ... or a sum of scaled fields of the topic (value = scale · Σ termᵢ.scale · termᵢ.field +
    /// offset: e.g. a velocity setpoint minus the velocity) ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terms: Option<Vec<Term>>,
    /// ... or an attitude setpoint as a quaternion `[w, x, y, z]` ...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quaternion: Option<[String; 4]>,
    /// ... or as ZYX Euler angles `[roll, pitch, yaw]` (times `scale`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub euler: Option<[String; 3]>,
    /// For an attitude setpoint: which angle, and its frames.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle: Option<Angle>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inertial: Option<Inertial>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body: Option<Body>,
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub scale: f64,
    #[serde(default, skip_serializing_if = "is_zero")]
    pub offset: f64,
    /// For an Euler setpoint: angles logged with the opposite sign (as `attitude.negate`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub negate: Vec<Angle>,
}

/// One term of an input's sum.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Term {
    pub field: String,
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub scale: f64,
}

fn one() -> f64 {
    1.0
}
fn is_one(v: &f64) -> bool {
    *v == 1.0
}
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl Profile {
    /// A preset by name, or a profile file by path (anything that is not a preset name).
    pub fn resolve(name_or_path: &str) -> Result<Profile, ImportError> {
        if let Some((_, text)) = PRESETS.iter().find(|(n, _)| *n == name_or_path) {
            return Profile::parse(text, &format!("preset `{name_or_path}`"));
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(ImportError::new(
                name_or_path,
                ImportErrorKind::Profile,
                format!(
                    "not a preset ({}) and no such profile file",
                    PRESETS.map(|(n, _)| n).join(", ")
                ),
            ));
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| ImportError::new(name_or_path, ImportErrorKind::Io, format!("cannot read: {e}")))?;
        Profile::parse(&text, name_or_path)
    }

    /// Parse and validate profile JSON; `label` names it in errors.
    pub fn parse(text: &str, label: &str) -> Result<Profile, ImportError> {
        let de = &mut serde_json::Deserializer::from_str(text);
        let profile: Profile = serde_path_to_error::deserialize(de).map_err(|e| {
            let path = e.path().to_string();
            ImportError::new(label, ImportErrorKind::Profile, format!("at `{path}`: {}", e.inner()))
        })?;
        profile.validate(label)?;
        Ok(profile)
    }

    fn validate(&self, label: &str) -> Result<(), ImportError> {
        let fail = |m: String| Err(ImportError::new(label, ImportErrorKind::Profile, m));
        if self.format != PROFILE_FORMAT {
            return fail(format!("`format` is `{}`, expected `{PROFILE_FORMAT}`", self.format));
        }
        if matches!(self.position.frame, VectorFrame::Flu | VectorFrame::Frd) {
            return fail("`position.frame` must be `enu` or `ned` (a position is not a body-frame vector)".into());
        }
        if self.attitude.quaternion.is_some() == self.attitude.euler.is_some() {
            return fail("`attitude` needs exactly one of `quaternion` and `euler`".into());
        }
        for (name, scale) in [
            ("attitude.scale", self.attitude.scale),
            ("rates.scale", self.rates.scale),
            ("position.scale", self.position.scale),
            ("velocity.scale", self.velocity.scale),
        ] {
            if !(scale.is_finite() && scale != 0.0) {
                return fail(format!("`{name}` must be a finite non-zero number, got {scale}"));
            }
        }
        for (name, input) in self.inputs.all() {
            let kinds = [
                input.field.is_some(),
                input.terms.is_some(),
                input.quaternion.is_some(),
                input.euler.is_some(),
            ];
            if kinds.iter().filter(|k| **k).count() != 1 {
                return fail(format!(
                    "`inputs.{name}` needs exactly one of `field`, `terms`, `quaternion` and `euler`"
                ));
            }
            if let Some(terms) = &input.terms {
                if terms.is_empty() || terms.iter().any(|t| !t.scale.is_finite()) {
                    return fail(format!("`inputs.{name}.terms`: at least one term, each `scale` finite"));
                }
            }
            if !input.negate.is_empty() && input.euler.is_none() {
                return fail(format!("`inputs.{name}.negate` is for Euler setpoints (`euler`)"));
            }
            let attitude = input.field.is_none() && input.terms.is_none();
            if attitude && (input.angle.is_none() || input.inertial.is_none() || input.body.is_none()) {
                return fail(format!(
                    "`inputs.{name}`: an attitude setpoint needs `angle` (roll, pitch or yaw), `inertial` and `body`"
                ));
            }
            if !attitude && (input.angle.is_some() || input.inertial.is_some() || input.body.is_some()) {
                return fail(format!(
                    "`inputs.{name}`: `angle`, `inertial` and `body` are for attitude setpoints, not a `field` or `terms`"
                ));
            }
            if !(input.scale.is_finite() && input.offset.is_finite()) {
                return fail(format!("`inputs.{name}`: `scale` and `offset` must be finite"));
            }
        }
        if !self.attitude.negate.is_empty() && self.attitude.euler.is_none() {
            return fail("`attitude.negate` is for Euler angles (`euler`), not a quaternion".into());
        }
        if !self.rates.negate.is_empty() && self.rates.kind != RatesKind::Euler {
            return fail("`rates.negate` is for Euler-angle rates (`kind`: `euler`)".into());
        }
        Ok(())
    }

    /// Every (topic, field) the profile reads, in profile order.
    pub fn needs(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        let mut add = |topic: &str, fields: &[String]| {
            for f in fields {
                let item = (topic.to_owned(), f.clone());
                if !out.contains(&item) {
                    out.push(item);
                }
            }
        };
        add(&self.position.topic, &self.position.fields);
        add(&self.velocity.topic, &self.velocity.fields);
        if let Some(q) = &self.attitude.quaternion {
            add(&self.attitude.topic, q);
        }
        if let Some(e) = &self.attitude.euler {
            add(&self.attitude.topic, e);
        }
        add(&self.rates.topic, &self.rates.fields);
        for (_, input) in self.inputs.all() {
            if let Some(f) = &input.field {
                add(&input.topic, std::slice::from_ref(f));
            }
            if let Some(terms) = &input.terms {
                let fields: Vec<String> = terms.iter().map(|t| t.field.clone()).collect();
                add(&input.topic, &fields);
            }
            if let Some(q) = &input.quaternion {
                add(&input.topic, q);
            }
            if let Some(e) = &input.euler {
                add(&input.topic, e);
            }
        }
        if let Some(b) = &self.battery_voltage {
            add(&b.topic, std::slice::from_ref(&b.field));
        }
        out
    }

    /// The profile as pretty JSON (as `--print-profile` shows it).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_parse() {
        for (name, _) in PRESETS {
            let p = Profile::resolve(name).unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(p.name, name);
            // Printing and reading back gives the same profile.
            assert_eq!(Profile::parse(&p.to_json(), name).unwrap(), p);
        }
    }

    #[test]
    fn bad_profiles_are_named() {
        let e = Profile::resolve("no-such-preset").unwrap_err();
        assert!(e.message.contains("not a preset (px4, mavros"), "{e}");
        let text = PRESETS[0].1.replace("\"ned\"", "\"nde\"");
        let e = Profile::parse(&text, "p.json").unwrap_err();
        assert!(e.to_string().starts_with("p.json: at `position.frame`"), "{e}");
    }
}
