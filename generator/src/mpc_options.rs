//! MPC problem options (`uavgen --mpc options.json`): weights, input bounds and
//! solver limits, with the defaults every command uses (the generator, `track`, `diagnose --plant`).
//! The defaults are the paper's except on the heading: q = 1 on yaw and r = 10 on u_yaw_rate
//! (`examples/mpc_paper.json` has the paper's own). See docs/mpc.md and docs/validation.md.

use crate::model::Model;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::Path;

/// The options file as written (every field optional).
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MpcOptionsFile {
    pub q: Option<Vec<f64>>,
    pub q_terminal: Option<Vec<f64>>,
    pub r: Option<Vec<f64>>,
    pub r_delta: Option<Vec<f64>>,
    pub u_min: Option<Vec<f64>>,
    pub u_max: Option<Vec<f64>>,
    pub max_qp_iterations: Option<usize>,
    pub max_qp_work: Option<usize>,
    pub max_ipm_iterations: Option<usize>,
    pub regularisation: Option<f64>,
    pub disturbance_gain: Option<f64>,
    pub disturbance_max_acceleration: Option<f64>,
    pub max_position_error: Option<f64>,
    pub recovery_speed: Option<f64>,
}

/// Validated options for one model.
#[derive(Debug, Clone, PartialEq)]
pub struct MpcOptions {
    /// Stage weights diag(Q), k = 0..N−1.
    pub q: Vec<f64>,
    /// Terminal weights diag(Q_N).
    pub q_terminal: Vec<f64>,
    /// Input weights diag(R).
    pub r: Vec<f64>,
    /// Input-rate weights diag(S) on uₖ − uₖ₋₁ (u₋₁ = the input sent last; docs/mpc.md).
    pub r_delta: Vec<f64>,
    pub u_min: Vec<f64>,
    pub u_max: Vec<f64>,
    /// Hard cap on active-set iterations per QP (`--qp condensed`).
    pub max_qp_iterations: usize,
    /// Work budget of one QP in multiply-adds (`--qp condensed`; None: NV³ = (N·NU)³, six full
    /// factorisations of the condensed Hessian, at most 2³² − 1). docs/mpc.md, "The work budget".
    pub max_qp_work: Option<usize>,
    /// Hard cap on interior-point iterations per QP (`--qp riccati`).
    pub max_ipm_iterations: usize,
    /// Added to the condensed Hessian's diagonal.
    pub regularisation: f64,
    /// Gain of the runtime's disturbance observer (0 = off; docs/mpc.md, "Offset-free tracking").
    pub disturbance_gain: f64,
    /// Bound of the estimated disturbance acceleration on vx, vy, vz (m/s²).
    pub disturbance_max_acceleration: f64,
    /// Largest position error (m, Euclidean over x, y, z) the QP is shown: farther from the
    /// reference the window is translated towards the aircraft (docs/mpc.md, "Recovery").
    pub max_position_error: f64,
    /// Speed (m/s) at which the point the QP chases moves towards the reference along the horizon
    /// beyond `max_position_error` (docs/mpc.md, "Recovery").
    pub recovery_speed: f64,
}

/// Default gain of the disturbance observer: each fresh measurement moves the estimate by half of
/// the velocity rows' one-sample prediction error (a time constant of about two samples). On
/// plants/m100_like.json it removes the slowly turning bias the shipped models leave on the spiral
/// and the circle (unmodelled drag, tilt gains). Slower observers (0.05–0.3) leave a model that lacks
/// its plant's command delay oscillating on the sinusoid (a nominal-plant model on
/// plants/effects/latency.json: 0.43–0.51 m against 0.29 m without an observer); 0.5 improves on no
/// observer in every case measured (docs/validation.md, "Offset-free tracking").
pub const DEFAULT_DISTURBANCE_GAIN: f64 = 0.5;

/// Default bound of the estimated disturbance acceleration (m/s²): the m100_like plant's drag is
/// 0.5 m/s² at the spiral's 6 m/s; a model's transient errors in a 3.6 m approach at the tilt bound
/// reach 1.7 m/s², which the bound keeps out of the estimate.
pub const DEFAULT_DISTURBANCE_MAX_ACCELERATION: f64 = 1.0;

/// The states whose one-sample prediction error the disturbance observer integrates: the world-frame
/// velocities, by name.
pub fn disturbance_rows(states: &[String]) -> Vec<bool> {
    states
        .iter()
        .map(|s| matches!(s.as_str(), "vx" | "vy" | "vz"))
        .collect()
}

/// Default `max_position_error` (m). With the default weights (no velocity weight, a 1 s horizon)
/// an error of 5 m already flies the shipped SINDy model into an orbit behind the circle (10 m
/// off the circle in x: back only after 20 s); 3 m recovers from every offset of docs/mpc.md,
/// "Recovery". Normal tracking errors (< 1 m) never reach it: tracking is unchanged.
pub const DEFAULT_MAX_POSITION_ERROR: f64 = 3.0;

/// Default `recovery_speed` (m/s): 100 m in about 15 s; at 3 m of chased error alone (0 m/s) the
/// approach takes 25–28 s from 100 m (docs/mpc.md, "Recovery").
pub const DEFAULT_RECOVERY_SPEED: f64 = 4.0;

/// Default cap on the Riccati interior-point iterations of one QP. Typical steps of the shipped
/// models need 9–12; after jumps and kicks pd_m100 reaches the cap on 12 of 12,002 measured steps
/// (docs/benchmarks.md, "Stage-wise QP"), where the last iterate is applied (`IterationCap`).
pub const DEFAULT_MAX_IPM_ITERATIONS: usize = 30;

/// Default weight of a state: 2 on positions x, y, z (the paper's), 1 on yaw (by name), 0
/// elsewhere (in particular on the extra states of a model's corrections).
///
/// The weight on yaw (the paper's is 0) and on u_yaw_rate ([`default_r`]) hold the heading: with
/// the paper's weights an MPC built from a delay-aware SINDy model, whose yaw-rate command couples
/// into roll and pitch, uses the yaw-rate command to tilt and oscillates on the circle (5–8 m RMSE
/// on plants/m100_like.json, docs/validation.md); with these, every delay-aware model there tracks.
fn default_q(model: &Model) -> Vec<f64> {
    model
        .states
        .iter()
        .map(|s| match s.as_str() {
            "x" | "y" | "z" => 2.0,
            "yaw" => 1.0,
            _ => 0.0,
        })
        .collect()
}

/// Default weight of an input: 10 on u_yaw_rate (by name; see [`default_q`]), the paper's 0.1 on
/// the others.
fn default_r(model: &Model) -> Vec<f64> {
    model
        .inputs
        .iter()
        .map(|n| if n == "u_yaw_rate" { 10.0 } else { 0.1 })
        .collect()
}

/// Default input-rate weight (S on uₖ − uₖ₋₁): 50 on u_roll and u_pitch (by name), 0 on the others.
///
/// Without it every delay-aware model's closed loop on plants/m100_like.json holds the path with roll
/// and pitch commands that swing across 20–80 % of their range every sample (docs/track.md
/// "Chatter"): a model whose attitude loops are slower than the aircraft's, measurement noise and
/// stale samples make the MPC's first input a high-gain feedback. S = 50 rad⁻² (a change of 0.1 rad
/// in one sample costs as much as 0.35 m of position error for one sample under q = 2) brings every
/// such loop below 1 % with the tracking RMSE within −0.04 … +0.01 m (docs/validation.md); 300
/// slows the approach (the spiral 0.31–0.34 m), 5–20 leaves the shipped models' roll at 11–19 %.
fn default_r_delta(model: &Model) -> Vec<f64> {
    model
        .inputs
        .iter()
        .map(|n| if n == "u_roll" || n == "u_pitch" { 50.0 } else { 0.0 })
        .collect()
}

/// Default bound of an input by name (the paper's), ±1 for other names.
fn default_bound(name: &str) -> f64 {
    match name {
        "u_vz" => 5.0,
        "u_roll" | "u_pitch" => 0.611,
        "u_yaw_rate" => 5.0 * PI / 6.0,
        _ => 1.0,
    }
}

impl MpcOptions {
    /// The QP work budget for a horizon of `horizon` samples: the set one or NV³, at most
    /// [`crate::validate::MPC_MAX_QP_WORK`] (2³² − 1, so that the constant fits a 32-bit target's
    /// usize).
    pub fn qp_work(&self, horizon: usize) -> usize {
        let nv = (horizon * self.u_min.len()) as u64;
        let default = nv
            .saturating_mul(nv)
            .saturating_mul(nv)
            .min(crate::validate::MPC_MAX_QP_WORK as u64) as usize;
        self.max_qp_work.unwrap_or(default)
    }

    /// The defaults for `model`: the paper's weights and bounds, except q = 1 on yaw and r = 10
    /// on u_yaw_rate (see [`default_q`]). The one place every command takes its defaults from.
    pub fn defaults(model: &Model) -> Self {
        let q = default_q(model);
        Self {
            q_terminal: q.clone(),
            q,
            r: default_r(model),
            r_delta: default_r_delta(model),
            u_min: model.inputs.iter().map(|n| -default_bound(n)).collect(),
            u_max: model.inputs.iter().map(|n| default_bound(n)).collect(),
            max_qp_iterations: 200,
            max_qp_work: None,
            max_ipm_iterations: DEFAULT_MAX_IPM_ITERATIONS,
            regularisation: 1e-9,
            disturbance_gain: DEFAULT_DISTURBANCE_GAIN,
            disturbance_max_acceleration: DEFAULT_DISTURBANCE_MAX_ACCELERATION,
            max_position_error: DEFAULT_MAX_POSITION_ERROR,
            recovery_speed: DEFAULT_RECOVERY_SPEED,
        }
    }

    /// `REFERENCE_ERROR_BOUND` of the generated crate: `max_position_error` on the states named
    /// x, y, z, `f64::INFINITY` (none) elsewhere.
    pub fn reference_error_bound(&self, states: &[String]) -> Vec<f64> {
        states
            .iter()
            .map(|s| {
                if matches!(s.as_str(), "x" | "y" | "z") {
                    self.max_position_error
                } else {
                    f64::INFINITY
                }
            })
            .collect()
    }

    /// `REFERENCE_APPROACH_RATE` (1/s): `recovery_speed` / `max_position_error`.
    pub fn reference_approach_rate(&self) -> f64 {
        self.recovery_speed / self.max_position_error
    }

    /// Per-sample bound of each state's disturbance eᵢ (x⁺ = F(x, u) + e): the maximum acceleration
    /// times `dt` on the rows of [`disturbance_rows`], 0 (not estimated) elsewhere and everywhere
    /// when the gain is 0.
    pub fn disturbance_bound(&self, states: &[String], dt: f64) -> Vec<f64> {
        disturbance_rows(states)
            .into_iter()
            .map(|on| {
                if on && self.disturbance_gain > 0.0 {
                    self.disturbance_max_acceleration * dt
                } else {
                    0.0
                }
            })
            .collect()
    }

    /// Defaults overridden by `file`, validated; `label` names the file in errors.
    pub fn from_file(model: &Model, file: MpcOptionsFile, label: &str) -> Result<Self, String> {
        let d = Self::defaults(model);
        let (nx, nu, base_nx) = (model.nx(), model.nu(), model.base_nx());
        let vector = |field: &str, v: Option<Vec<f64>>, default: Vec<f64>, n: usize| -> Result<Vec<f64>, String> {
            let mut v = v.unwrap_or(default);
            // State weights written for the model without its corrections: the extra states get 0.
            if field.starts_with('q') && base_nx < nx && v.len() == base_nx {
                v.resize(nx, 0.0);
            }
            if v.len() != n {
                let or_base = if field.starts_with('q') && base_nx < nx {
                    format!(" (or {base_nx}: the extra states of the corrections then weigh 0)")
                } else {
                    String::new()
                };
                return Err(format!(
                    "{label}: {field}: expected {n} values{or_base}, found {}",
                    v.len()
                ));
            }
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(format!("{label}: {field}[{i}]: non-finite value"));
            }
            // Weights and bounds have documented ranges (docs/mpc.md#ranges): beyond them the
            // condensed QP overflows or the solver returns inputs no vehicle accepts.
            for (i, &x) in v.iter().enumerate() {
                let checked = if field.starts_with('u') {
                    crate::validate::bounded(x, crate::validate::MPC_BOUND_MAX_ABS)
                } else {
                    crate::validate::within(x, crate::validate::MPC_WEIGHT, "")
                };
                checked.map_err(|m| format!("{label}: {field}[{i}]: {m}"))?;
            }
            Ok(v)
        };
        let q = vector("q", file.q, d.q, nx)?;
        let q_terminal = vector("q_terminal", file.q_terminal, q.clone(), nx)?;
        let r = vector("r", file.r, d.r, nu)?;
        let r_delta = vector("r_delta", file.r_delta, d.r_delta, nu)?;
        let u_min = vector("u_min", file.u_min, d.u_min, nu)?;
        let u_max = vector("u_max", file.u_max, d.u_max, nu)?;
        for (field, v) in [("q", &q), ("q_terminal", &q_terminal), ("r", &r), ("r_delta", &r_delta)] {
            if let Some(i) = v.iter().position(|&x| x < 0.0) {
                return Err(format!("{label}: {field}[{i}]: weights must be ≥ 0, found {}", v[i]));
            }
        }
        if let Some(i) = (0..nu).find(|&i| u_min[i] >= u_max[i]) {
            return Err(format!(
                "{label}: u_min[{i}] = {} must be below u_max[{i}] = {} (input '{}')",
                u_min[i], u_max[i], model.inputs[i]
            ));
        }
        let max_qp_iterations = file.max_qp_iterations.unwrap_or(d.max_qp_iterations);
        if !(1..=crate::validate::MPC_MAX_QP_ITERATIONS).contains(&max_qp_iterations) {
            return Err(format!(
                "{label}: max_qp_iterations must be between 1 and {}, found {max_qp_iterations}",
                crate::validate::MPC_MAX_QP_ITERATIONS
            ));
        }
        if let Some(work) = file.max_qp_work {
            if !(1..=crate::validate::MPC_MAX_QP_WORK).contains(&work) {
                return Err(format!(
                    "{label}: max_qp_work must be between 1 and {} multiply-adds, found {work}",
                    crate::validate::MPC_MAX_QP_WORK
                ));
            }
        }
        let max_ipm_iterations = file.max_ipm_iterations.unwrap_or(d.max_ipm_iterations);
        if !(1..=crate::validate::MPC_MAX_QP_ITERATIONS).contains(&max_ipm_iterations) {
            return Err(format!(
                "{label}: max_ipm_iterations must be between 1 and {}, found {max_ipm_iterations}",
                crate::validate::MPC_MAX_QP_ITERATIONS
            ));
        }
        let regularisation = file.regularisation.unwrap_or(d.regularisation);
        crate::validate::within(regularisation, crate::validate::MPC_REGULARISATION, "")
            .map_err(|m| format!("{label}: regularisation: {m}"))?;
        let disturbance_gain = file.disturbance_gain.unwrap_or(d.disturbance_gain);
        crate::validate::within(disturbance_gain, (0.0, 1.0), "")
            .map_err(|m| format!("{label}: disturbance_gain: {m}"))?;
        let disturbance_max_acceleration = file
            .disturbance_max_acceleration
            .unwrap_or(d.disturbance_max_acceleration);
        crate::validate::within(disturbance_max_acceleration, (0.0, 100.0), "m/s²")
            .map_err(|m| format!("{label}: disturbance_max_acceleration: {m}"))?;
        let max_position_error = file.max_position_error.unwrap_or(d.max_position_error);
        crate::validate::within(max_position_error, (0.01, 1e4), "m")
            .map_err(|m| format!("{label}: max_position_error: {m}"))?;
        let recovery_speed = file.recovery_speed.unwrap_or(d.recovery_speed);
        crate::validate::within(recovery_speed, (0.0, 100.0), "m/s")
            .map_err(|m| format!("{label}: recovery_speed: {m}"))?;
        Ok(Self {
            q,
            q_terminal,
            r,
            r_delta,
            u_min,
            u_max,
            max_qp_iterations,
            max_qp_work: file.max_qp_work,
            max_ipm_iterations,
            regularisation,
            disturbance_gain,
            disturbance_max_acceleration,
            max_position_error,
            recovery_speed,
        })
    }

    /// Read and validate an options file for `model`.
    pub fn load(model: &Model, path: &Path) -> Result<Self, String> {
        let label = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| format!("{label}: cannot read: {e}"))?;
        Self::parse(model, &text, &label)
    }

    /// Validate options text for `model`; `label` names the file in errors.
    pub fn parse(model: &Model, text: &str, label: &str) -> Result<Self, String> {
        let text = crate::validate::strip_bom(text);
        let mut de = serde_json::Deserializer::from_str(text);
        let file: MpcOptionsFile = serde_path_to_error::deserialize(&mut de).map_err(|e| {
            let path = e.path().to_string();
            let inner = e.into_inner().to_string();
            if path == "." {
                format!("{label}: {inner}")
            } else {
                format!("{label}: {path}: {inner}")
            }
        })?;
        de.end().map_err(|e| format!("{label}: {e}"))?;
        Self::from_file(model, file, label)
    }
}
