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
    /// Other sources of the same channel, tried in order when the file lacks this one's topic
    /// or fields (older versions of a flight stack): the first present with a finite sample is
    /// used ([`Profile::choose`]).
    #[serde(default, rename = "or", skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<Vector>,
    /// Free text shown when this source is chosen (e.g. `PX4 v1.5–1.9`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
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
    /// Other sources of the same channel, tried in order when the file lacks this one's topic
    /// or fields (older versions of a flight stack): the first present with a finite sample is
    /// used ([`Profile::choose`]).
    #[serde(default, rename = "or", skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<Attitude>,
    /// Free text shown when this source is chosen (e.g. `PX4 v1.5–1.9`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
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
    /// Other sources of the same channel, tried in order when the file lacks this one's topic
    /// or fields (older versions of a flight stack): the first present with a finite sample is
    /// used ([`Profile::choose`]).
    #[serde(default, rename = "or", skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<Rates>,
    /// Free text shown when this source is chosen (e.g. `PX4 v1.5–1.9`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
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
    /// Other sources of the same channel, tried in order when the file lacks this one's topic
    /// or fields (older versions of a flight stack): the first present with a finite sample is
    /// used ([`Profile::choose`]).
    #[serde(default, rename = "or", skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<Scalar>,
    /// Free text shown when this source is chosen (e.g. `PX4 v1.5–1.9`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
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
    /// Other sources of the same channel, tried in order when the file lacks this one's topic
    /// or fields (older versions of a flight stack): the first present with a finite sample is
    /// used ([`Profile::choose`]).
    #[serde(default, rename = "or", skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<Input>,
    /// Free text shown when this source is chosen (e.g. `PX4 v1.5–1.9`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub note: String,
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
        self.validate_one(label)?;
        for (ch, (name, _)) in CHANNELS.iter().enumerate() {
            let mut k = 1;
            while self.candidate_of(ch, k).is_some() {
                let p = self.with_candidate(ch, k);
                let nested = match ch {
                    0 => self.position.nested(),
                    1 => self.velocity.nested(),
                    2 => self.attitude.nested(),
                    3 => self.rates.nested(),
                    4 => self.inputs.u_vz.nested(),
                    5 => self.inputs.u_roll.nested(),
                    6 => self.inputs.u_pitch.nested(),
                    7 => self.inputs.u_yaw_rate.nested(),
                    _ => self.battery_voltage.as_ref().is_some_and(|b| b.nested()),
                };
                if nested {
                    return Err(ImportError::new(
                        label,
                        ImportErrorKind::Profile,
                        format!(
                            "`{name}.or[{}]` has an `or` of its own: list every alternative in `{name}.or`",
                            k - 1
                        ),
                    ));
                }
                p.validate_one(label).map_err(|e| ImportError {
                    message: format!("`{name}.or[{}]`: {}", k - 1, e.message),
                    ..e
                })?;
                k += 1;
            }
        }
        Ok(())
    }

    fn validate_one(&self, label: &str) -> Result<(), ImportError> {
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

    /// Every (topic, field) the profile reads, in profile order (every alternative's too).
    pub fn needs(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        for ch in 0..CHANNELS.len() {
            let mut k = 0;
            while let Some((topic, fields, _)) = self.candidate_of(ch, k) {
                for f in fields {
                    let item = (topic.clone(), f);
                    if !out.contains(&item) {
                        out.push(item);
                    }
                }
                k += 1;
            }
        }
        out
    }

    /// The profile as pretty JSON (as `--print-profile` shows it).
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }
}

/// A channel source with alternatives (every mapping struct of a profile).
trait Source: Clone {
    fn alternatives(&self) -> &[Self];
    fn alternatives_mut(&mut self) -> &mut Vec<Self>;
    fn note(&self) -> &str;
    fn topic(&self) -> &str;
    /// Every field it reads.
    fn fields(&self) -> Vec<String>;
    /// Candidate `k` (0: itself), without alternatives.
    fn candidate(&self, k: usize) -> Self {
        let mut c = if k == 0 {
            self.clone()
        } else {
            self.alternatives()[k - 1].clone()
        };
        c.alternatives_mut().clear();
        c
    }
    fn candidates(&self) -> usize {
        1 + self.alternatives().len()
    }
    /// Whether an alternative has alternatives of its own.
    fn nested(&self) -> bool {
        self.alternatives().iter().any(|a| !a.alternatives().is_empty())
    }
}

macro_rules! source {
    ($t:ty, |$s:ident| $fields:expr) => {
        impl Source for $t {
            fn alternatives(&self) -> &[Self] {
                &self.alternatives
            }
            fn alternatives_mut(&mut self) -> &mut Vec<Self> {
                &mut self.alternatives
            }
            fn note(&self) -> &str {
                &self.note
            }
            fn topic(&self) -> &str {
                &self.topic
            }
            fn fields(&$s) -> Vec<String> {
                $fields
            }
        }
    };
}

source!(Vector, |self| self.fields.to_vec());
source!(Rates, |self| self.fields.to_vec());
source!(Scalar, |self| vec![self.field.clone()]);
source!(Attitude, |self| {
    let mut f: Vec<String> = self.quaternion.iter().flatten().cloned().collect();
    f.extend(self.euler.iter().flatten().cloned());
    f
});
source!(Input, |self| {
    let mut f: Vec<String> = self.field.iter().cloned().collect();
    f.extend(self.terms.iter().flatten().map(|t| t.field.clone()));
    f.extend(self.quaternion.iter().flatten().cloned());
    f.extend(self.euler.iter().flatten().cloned());
    f
});

/// The channels of a profile, as named in messages (JSON paths) with the contract columns they
/// feed.
pub const CHANNELS: [(&str, &str); 9] = [
    ("position", "x, y, z"),
    ("velocity", "vx, vy, vz"),
    ("attitude", "roll, pitch, yaw"),
    ("rates", "roll_rate, pitch_rate, yaw_rate"),
    ("inputs.u_vz", "u_vz"),
    ("inputs.u_roll", "u_roll"),
    ("inputs.u_pitch", "u_pitch"),
    ("inputs.u_yaw_rate", "u_yaw_rate"),
    ("battery_voltage", "battery_voltage"),
];

/// What [`Profile::choose`] needs to know of a recording.
pub trait Available {
    /// Whether `topic` is in the file with every one of `fields`, and has a sample where they are
    /// all finite (`Some(false)`: present, no such sample; `None`: topic or a field missing).
    fn usable(&self, topic: &str, fields: &[String]) -> Option<bool>;
    /// The file's topics (for the message when no source is present).
    fn topics(&self) -> Vec<String>;
    /// A topic's fields, if the file has it.
    fn fields(&self, topic: &str) -> Option<Vec<String>>;
}

impl Profile {
    /// (topic, fields, note) of candidate `k` of channel `ch` (an index of [`CHANNELS`]); `None`
    /// past the last candidate (or no battery mapping).
    fn candidate_of(&self, ch: usize, k: usize) -> Option<(String, Vec<String>, String)> {
        fn get<T: Source>(x: &T, k: usize) -> Option<(String, Vec<String>, String)> {
            (k < x.candidates()).then(|| {
                let c = x.candidate(k);
                (c.topic().to_owned(), c.fields(), c.note().to_owned())
            })
        }
        match ch {
            0 => get(&self.position, k),
            1 => get(&self.velocity, k),
            2 => get(&self.attitude, k),
            3 => get(&self.rates, k),
            4 => get(&self.inputs.u_vz, k),
            5 => get(&self.inputs.u_roll, k),
            6 => get(&self.inputs.u_pitch, k),
            7 => get(&self.inputs.u_yaw_rate, k),
            _ => self.battery_voltage.as_ref().and_then(|b| get(b, k)),
        }
    }

    /// This profile with channel `ch` taking candidate `k` (and no alternatives left there).
    fn with_candidate(&self, ch: usize, k: usize) -> Profile {
        let mut p = self.clone();
        match ch {
            0 => p.position = self.position.candidate(k),
            1 => p.velocity = self.velocity.candidate(k),
            2 => p.attitude = self.attitude.candidate(k),
            3 => p.rates = self.rates.candidate(k),
            4 => p.inputs.u_vz = self.inputs.u_vz.candidate(k),
            5 => p.inputs.u_roll = self.inputs.u_roll.candidate(k),
            6 => p.inputs.u_pitch = self.inputs.u_pitch.candidate(k),
            7 => p.inputs.u_yaw_rate = self.inputs.u_yaw_rate.candidate(k),
            _ => p.battery_voltage = self.battery_voltage.as_ref().map(|b| b.candidate(k)),
        }
        p
    }

    /// Whether any channel has alternatives.
    pub fn has_alternatives(&self) -> bool {
        (0..CHANNELS.len()).any(|ch| self.candidate_of(ch, 1).is_some())
    }

    /// The profile with one source per channel for a file: for each channel the first candidate
    /// (itself, then its `or` list) whose topic and fields the file has with a finite sample, else
    /// the first whose topic and fields it has, else itself (whose absence the import then
    /// names). Also one line per channel saying which source was chosen (when the profile has
    /// alternatives; empty otherwise). A channel none of whose several sources is in the file is an
    /// error listing them.
    pub fn choose(&self, file: &str, rec: &dyn Available) -> Result<(Profile, Vec<String>), ImportError> {
        let mut out = self.clone();
        let mut lines = Vec::new();
        let report = self.has_alternatives();
        for (ch, (name, columns)) in CHANNELS.iter().enumerate() {
            let mut cands = Vec::new();
            let mut k = 0;
            while let Some(c) = self.candidate_of(ch, k) {
                cands.push(c);
                k += 1;
            }
            if cands.is_empty() {
                continue;
            }
            let state: Vec<Option<bool>> = cands.iter().map(|(t, f, _)| rec.usable(t, f)).collect();
            let pick = state
                .iter()
                .position(|s| *s == Some(true))
                .or_else(|| state.iter().position(|s| s.is_some()));
            let Some(pick) = pick else {
                if cands.len() > 1 && ch < 8 {
                    let listed: Vec<String> = cands
                        .iter()
                        .map(|(t, f, _)| match rec.fields(t) {
                            None => format!("`{t}` ({}): no such topic", f.join(", ")),
                            Some(have) => {
                                let missing: Vec<&String> = f.iter().filter(|x| !have.contains(x)).collect();
                                format!(
                                    "`{t}` has no numeric field {} (its fields are {})",
                                    super::error::list_names(&missing, 5),
                                    super::error::list_names(&have, 40)
                                )
                            }
                        })
                        .collect();
                    let topic_there = cands.iter().any(|(t, _, _)| rec.fields(t).is_some());
                    return Err(ImportError::new(
                        file,
                        if topic_there {
                            ImportErrorKind::MissingField
                        } else {
                            ImportErrorKind::MissingTopic
                        },
                        format!(
                            "{columns}: none of profile `{}`'s sources for `{name}` is in this file: {}; the file has the topics {}",
                            self.name,
                            listed.join("; "),
                            super::error::list_names(&rec.topics(), 60)
                        ),
                    ));
                }
                continue;
            };
            out = out.with_candidate(ch, pick);
            if report {
                let (t, f, note) = &cands[pick];
                let which = match cands.len() {
                    1 => String::new(),
                    n => format!(
                        " (source {} of {n}{})",
                        pick + 1,
                        if note.is_empty() {
                            String::new()
                        } else {
                            format!(": {note}")
                        }
                    ),
                };
                lines.push(format!("{columns} ← `{t}` {}{which}", f.join(", ")));
            }
        }
        Ok((out, lines))
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
