//! [`simulate`]: fly a list of profiles, one segment each, and return the log rows.

use super::error::PlantError;
use super::plant::Plant;
use super::plant_file::PlantFile;
use super::profiles::{Pilot, Profile};
use serde::Serialize;

/// Default pause between segments, s (the time column jumps by duration + gap, as in the
/// RotorPy logs).
pub const DEFAULT_SEGMENT_GAP: f64 = 2.0;

/// The longest segment accepted, s (a guard against typos such as `--duration 6e6`).
pub const MAX_DURATION_S: f64 = 24.0 * 3600.0;

/// The most log rows one simulation may produce (memory guard).
pub const MAX_ROWS: f64 = 10_000_000.0;

/// What to fly.
#[derive(Clone, Debug, PartialEq)]
pub struct SimulateOptions {
    /// One segment per profile, in order.
    pub profiles: Vec<Profile>,
    /// Seconds per segment, as many as profiles.
    pub durations: Vec<f64>,
    pub seed: u64,
    /// Pause between segments, s.
    pub segment_gap: f64,
}

impl SimulateOptions {
    pub fn new(profiles: Vec<Profile>, durations: Vec<f64>, seed: u64) -> Self {
        Self {
            profiles,
            durations,
            seed,
            segment_gap: DEFAULT_SEGMENT_GAP,
        }
    }

    /// Parse comma lists: `--profile excite,circle --duration 60,30`.
    pub fn parse(profiles: &str, durations: &str, seed: u64) -> Result<Self, PlantError> {
        let profiles = Profile::parse_list(profiles)?;
        let durations = durations
            .split(',')
            .map(|d| {
                d.trim()
                    .parse::<f64>()
                    .map_err(|_| PlantError::option("--duration", format!("`{}` is not a number of seconds", d.trim())))
            })
            .collect::<Result<Vec<f64>, _>>()?;
        let options = Self::new(profiles, durations, seed);
        options.validate()?;
        Ok(options)
    }

    pub fn validate(&self) -> Result<(), PlantError> {
        if self.profiles.is_empty() {
            return Err(PlantError::option("--profile", "at least one profile is required"));
        }
        if self.durations.len() != self.profiles.len() {
            return Err(PlantError::option(
                "--duration",
                format!(
                    "{} durations for {} profiles: give one duration per profile",
                    self.durations.len(),
                    self.profiles.len()
                ),
            ));
        }
        for d in &self.durations {
            if !(d.is_finite() && *d > 0.0 && *d <= MAX_DURATION_S) {
                return Err(PlantError::option(
                    "--duration",
                    format!("{d} s: a duration must be positive and at most {MAX_DURATION_S} s"),
                ));
            }
        }
        if !(self.segment_gap.is_finite() && self.segment_gap >= 0.0) {
            return Err(PlantError::option(
                "segment_gap",
                format!("{} s: must be a finite number ≥ 0", self.segment_gap),
            ));
        }
        Ok(())
    }
}

/// One logged sample.
#[derive(Clone, Debug, PartialEq)]
pub struct LogRow {
    pub t: f64,
    /// The measured states (noise, sample-and-hold), log order, continuous yaw.
    pub x: [f64; 12],
    /// The command as the autopilot accepted it (clamped), applied from t to the next sample.
    pub u: [f64; 4],
    /// Logged (measured) voltage, V.
    pub battery_voltage: f64,
    pub segment: usize,
    /// The true states, continuous yaw (not written to the CSV).
    pub true_x: [f64; 12],
    /// The row repeats the previous row's states (sample-and-hold).
    pub held: bool,
}

/// Figures of one segment (true states).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SegmentSummary {
    pub segment: usize,
    pub profile: String,
    pub duration_s: f64,
    pub rows: usize,
    pub t_start: f64,
    pub min_z: f64,
    pub max_z: f64,
    pub max_abs_xy: f64,
    pub max_tilt_rad: f64,
    pub max_speed: f64,
    /// Fraction of RK4 substeps whose thrust command was clamped.
    pub thrust_saturation_fraction: f64,
    pub ground_effect_max_thrust_ratio: f64,
    pub battery_voltage_end: f64,
    pub thrust_per_command_factor_end: f64,
    pub held_rows: usize,
}

/// The result of [`simulate`].
#[derive(Clone, Debug, PartialEq)]
pub struct SimulatedLog {
    /// `# key: value` lines, in order.
    pub metadata: Vec<(String, String)>,
    pub rows: Vec<LogRow>,
    pub segments: Vec<SegmentSummary>,
    pub rate_hz: f64,
}

impl SimulatedLog {
    /// The same flight logged without sensor noise: every row's true states, except that a held
    /// row repeats the previous row as in the measured log (sample-and-hold is part of the logging,
    /// not of the noise). The self-check scores the model gap on it (`docs/diagnosis.md`).
    pub fn noise_free(&self) -> SimulatedLog {
        let mut out = self.clone();
        let mut previous: Option<([f64; 12], usize)> = None;
        for r in &mut out.rows {
            r.x = match previous {
                Some((x, segment)) if r.held && segment == r.segment => x,
                _ => r.true_x,
            };
            previous = Some((r.x, r.segment));
        }
        out.metadata
            .push(("sensor_noise".into(), "removed: true states, held rows kept".into()));
        out
    }
}

/// Fly `opts.profiles` with the plant of `file`. Deterministic for a given seed.
pub fn simulate(file: &PlantFile, opts: &SimulateOptions) -> Result<SimulatedLog, PlantError> {
    file.validate()?;
    opts.validate()?;
    let rows_needed: f64 = opts
        .durations
        .iter()
        .map(|d| (d * file.integration.rate_hz).round())
        .sum();
    if rows_needed > MAX_ROWS {
        return Err(PlantError::option(
            "--duration",
            format!(
                "{rows_needed} rows at {} Hz: at most {MAX_ROWS} rows per simulation",
                file.integration.rate_hz
            ),
        ));
    }
    let mut plant = Plant::new(file, opts.seed);
    let mut rows = Vec::new();
    let mut segments = Vec::new();
    let mut t_start = 0.0;
    for (index, (&profile, &duration)) in opts.profiles.iter().zip(&opts.durations).enumerate() {
        if index > 0 {
            plant.skip(t_start - plant.time());
        }
        let mut pilot = Pilot::new(profile, opts.seed, index as u64, file.vehicle.gravity);
        plant.reset(&pilot.start());
        plant.reset_stats();
        let n = (duration * file.integration.rate_hz).round().max(1.0) as usize;
        let first = rows.len();
        for k in 0..n {
            let t = k as f64 * plant.sample_period();
            let x = plant.measured();
            let u = pilot.command(t, &x);
            let (true_x, voltage, held) = (plant.true_state(), plant.battery_voltage(), plant.measurement_held());
            plant.step(&u);
            rows.push(LogRow {
                t: t_start + t,
                x,
                u: plant.command(),
                battery_voltage: voltage,
                segment: index,
                true_x,
                held,
            });
        }
        segments.push(summary(index, profile, duration, t_start, &rows[first..], &plant));
        t_start += duration + opts.segment_gap;
    }
    let list = |v: Vec<String>| v.join(",");
    let effects = file.effects.active();
    let metadata = vec![
        ("format".into(), "uavgen flight log v1".into()),
        (
            "source".into(),
            format!("uavgen simulate {}", env!("CARGO_PKG_VERSION")),
        ),
        ("plant".into(), file.source.clone()),
        ("vehicle".into(), file.name.clone()),
        (
            "effects".into(),
            if effects.is_empty() {
                "none".into()
            } else {
                effects.join(",")
            },
        ),
        ("rate_hz".into(), format!("{}", file.integration.rate_hz)),
        (
            "profile".into(),
            list(opts.profiles.iter().map(|p| p.name().to_owned()).collect()),
        ),
        (
            "duration_s".into(),
            list(opts.durations.iter().map(|d| format!("{d}")).collect()),
        ),
        ("seed".into(), opts.seed.to_string()),
        (
            "frame".into(),
            "ENU, z up; Euler ZYX; Euler-angle rates; yaw wrapped to (-pi, pi]".into(),
        ),
        ("segments".into(), segments.len().to_string()),
    ];
    Ok(SimulatedLog {
        metadata,
        rows,
        segments,
        rate_hz: file.integration.rate_hz,
    })
}

fn summary(
    segment: usize,
    profile: Profile,
    duration: f64,
    t_start: f64,
    rows: &[LogRow],
    plant: &Plant,
) -> SegmentSummary {
    let stats = plant.stats();
    let fold = |f: &dyn Fn(&LogRow) -> f64, init: f64, pick: fn(f64, f64) -> f64| rows.iter().map(f).fold(init, pick);
    let tilt = |r: &LogRow| (r.true_x[3].cos() * r.true_x[4].cos()).clamp(-1.0, 1.0).acos();
    SegmentSummary {
        segment,
        profile: profile.name().into(),
        duration_s: duration,
        rows: rows.len(),
        t_start,
        min_z: fold(&|r| r.true_x[2], f64::INFINITY, f64::min),
        max_z: fold(&|r| r.true_x[2], f64::NEG_INFINITY, f64::max),
        max_abs_xy: fold(&|r| r.true_x[0].abs().max(r.true_x[1].abs()), 0.0, f64::max),
        max_tilt_rad: fold(&tilt, 0.0, f64::max),
        max_speed: fold(
            &|r| (r.true_x[6].powi(2) + r.true_x[7].powi(2) + r.true_x[8].powi(2)).sqrt(),
            0.0,
            f64::max,
        ),
        thrust_saturation_fraction: if stats.substeps > 0 {
            stats.thrust_saturated as f64 / stats.substeps as f64
        } else {
            0.0
        },
        ground_effect_max_thrust_ratio: stats.max_ground_ratio,
        battery_voltage_end: plant.true_battery_voltage(),
        thrust_per_command_factor_end: plant.thrust_factor(),
        held_rows: rows.iter().filter(|r| r.held).count(),
    }
}
