//! Is an identified model fit for an MPC? One horizon of free run, from random states of the
//! operating envelope under constant (often saturated) inputs, must stay finite and bounded.
//!
//! A model that fits one-step derivatives can still explode within a second at inputs the logs never
//! held for long (a quadratic term at a saturated input, say); inside an MPC that makes the
//! predictions, and the QP built on them, meaningless. `uavgen identify` runs this check on every
//! model it writes (docs/identification.md).

use super::excitation::Excitation;
use crate::discretize::{auto_substeps, discrete_step, Envelope};
use crate::ir::ModelIr;
use crate::model::Model;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The trials of the check and the bounds a bounded prediction respects.
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonCheck {
    /// Random start states (plus hover with zero input).
    pub trials: usize,
    /// Samples of one horizon and the sample period (s).
    pub horizon: usize,
    pub dt: f64,
    /// Start states: |roll|, |pitch| ≤ tilt (rad), |v| ≤ speed (m/s), |Euler rates| ≤ rate (rad/s),
    /// yaw within `yaw` (anywhere when `None`); inputs uniform in ±`inputs`, half of the trials at
    /// a saturated corner.
    pub tilt: f64,
    pub speed: f64,
    pub rate: f64,
    pub inputs: [f64; 4],
    /// The start yaw range (rad): what the logs support when their heading did not move
    /// ([`super::excitation::Excitation::yaw_range`]); `None`: the whole circle.
    pub yaw: Option<(f64, f64)>,
    /// A prediction is unbounded if |v| ≥ max_speed, |roll| or |pitch| ≥ max_tilt, or an Euler rate
    /// ≥ max_rate, or anything is not finite.
    pub max_speed: f64,
    pub max_tilt: f64,
    pub max_rate: f64,
    pub seed: u64,
}

impl Default for HorizonCheck {
    /// 256 trials of 30 samples at 30 Hz (the paper's MPC horizon), the MPC's input bounds; start
    /// states within tilt 0.5 rad, speed 4 m/s, rates 1 rad/s, any yaw; bounds |v| < 30 m/s, tilt < 1.5 rad,
    /// rates < 15 rad/s (a model without any attitude dynamics, whose rates stay at their start
    /// values, stays inside them for one second).
    fn default() -> Self {
        let envelope = Envelope::default();
        Self {
            trials: 256,
            horizon: 30,
            dt: 1.0 / 30.0,
            tilt: 0.5,
            speed: 4.0,
            rate: 1.0,
            inputs: envelope.inputs,
            yaw: None,
            max_speed: 30.0,
            max_tilt: 1.5,
            max_rate: 15.0,
            seed: 0,
        }
    }
}

impl HorizonCheck {
    /// The check of a model identified on logs analysed as `ex` (docs/identification.md,
    /// "Unexcited directions"): the defaults, with the inputs within the logged range widened
    /// ([`Excitation::check_inputs`]: ± 1.5 × the largest logged |command|) instead of the MPC's
    /// bounds, and the start yaw within the logged arc when the heading did not move.
    pub fn for_excitation(ex: &Excitation) -> Self {
        HorizonCheck {
            yaw: ex.heading_still.then(|| ex.yaw_range()).flatten(),
            inputs: ex.check_inputs(),
            ..HorizonCheck::default()
        }
    }
}

/// The first trial that left the bounds.
#[derive(Clone, Debug, PartialEq)]
pub struct Unbounded {
    pub x0: Vec<f64>,
    pub u: Vec<f64>,
    /// The sample (1-based) at which it left the bounds, and the state then.
    pub at: usize,
    pub x: Vec<f64>,
}

/// What [`check`] found.
#[derive(Clone, Debug, PartialEq)]
pub struct HorizonReport {
    pub trials: usize,
    pub unbounded: usize,
    pub first: Option<Unbounded>,
    pub substeps: usize,
}

impl HorizonReport {
    pub fn passed(&self) -> bool {
        self.unbounded == 0
    }

    pub fn summary(&self) -> String {
        match &self.first {
            None => format!(
                "horizon check: {} trials of one horizon from random envelope states stayed bounded",
                self.trials
            ),
            Some(f) => format!(
                "horizon check: {} of {} trials left the bounds; the first at sample {} from x0 = {:?} under u = {:?}, reaching {:?}",
                self.unbounded,
                self.trials,
                f.at,
                round(&f.x0),
                round(&f.u),
                round(&f.x)
            ),
        }
    }
}

fn round(v: &[f64]) -> Vec<f64> {
    v.iter().map(|a| (a * 1e3).round() / 1e3).collect()
}

/// Run the check on a model with the 12 standard states and 4 inputs (LOG_FORMAT.md order),
/// plus the extra states of its `corrections` (an input lag state `<input>_lagged` starts anywhere
/// within that input's bounds, so a trial also sees the lag catch up with a changed command; an
/// acceleration lag state and `flight_time` start at 0); other models are not checked (`None`).
pub fn check(model: &Model, options: &HorizonCheck) -> Option<HorizonReport> {
    if model.base_states() != crate::model::DEFAULT_STATES || model.inputs != crate::model::DEFAULT_INPUTS {
        return None;
    }
    let nx = model.nx();
    let lagged: Vec<Option<usize>> = model.states[12..]
        .iter()
        .map(|s| {
            crate::model::DEFAULT_INPUTS
                .iter()
                .position(|i| s.strip_suffix("_lagged") == Some(*i))
        })
        .collect();
    let ir = ModelIr::new(model);
    let substeps = auto_substeps(&ir, options.dt, &Envelope::default())
        .map(|c| c.substeps)
        .unwrap_or(4);
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let mut report = HorizonReport {
        trials: options.trials + 1,
        unbounded: 0,
        first: None,
        substeps,
    };
    for trial in 0..=options.trials {
        let mut x0 = vec![0.0; nx];
        let mut u = vec![0.0; 4];
        if trial > 0 {
            let mut uniform = |b: f64| rng.gen_range(-b..=b);
            for i in 3..5 {
                x0[i] = uniform(options.tilt);
            }
            // One draw either way (the same random sequence with or without a yaw range).
            x0[5] = match options.yaw {
                Some((lo, hi)) => 0.5 * (lo + hi) + uniform(0.5 * (hi - lo).abs()),
                None => uniform(std::f64::consts::PI),
            };
            for i in 6..9 {
                x0[i] = uniform(options.speed);
            }
            for i in 9..12 {
                x0[i] = uniform(options.rate);
            }
            for (j, b) in options.inputs.iter().enumerate() {
                u[j] = uniform(*b);
                if trial % 2 == 0 {
                    u[j] = b.copysign(u[j]);
                }
            }
            for (e, input) in lagged.iter().enumerate() {
                if let Some(j) = input {
                    x0[12 + e] = uniform(options.inputs[*j]);
                }
            }
        }
        let mut x = x0.clone();
        for k in 1..=options.horizon {
            x = discrete_step(&ir, &x, &u, options.dt, substeps);
            if !bounded(&x, options) {
                report.unbounded += 1;
                report.first.get_or_insert(Unbounded {
                    x0: x0.clone(),
                    u: u.clone(),
                    at: k,
                    x: x.clone(),
                });
                break;
            }
        }
    }
    Some(report)
}

fn bounded(x: &[f64], o: &HorizonCheck) -> bool {
    x.iter().all(|v| v.is_finite())
        && x[6..9].iter().all(|v| v.abs() < o.max_speed)
        && x[3..5].iter().all(|v| v.abs() < o.max_tilt)
        && x[9..12].iter().all(|v| v.abs() < o.max_rate)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(json: &str) -> Model {
        crate::model::parse(json, "test.json").unwrap()
    }

    fn sindy(extra: &str) -> String {
        let mut coefs = vec![
            r#"{"state":"vx","term":"vx","coefficient":-0.5}"#.to_string(),
            r#"{"state":"vy","term":"vy","coefficient":-0.5}"#.to_string(),
            r#"{"state":"vz","term":"vz","coefficient":-2.0}"#.to_string(),
            r#"{"state":"vz","term":"u_vz","coefficient":2.0}"#.to_string(),
            r#"{"state":"roll_rate","term":"roll","coefficient":-16.0}"#.to_string(),
            r#"{"state":"roll_rate","term":"roll_rate","coefficient":-3.0}"#.to_string(),
            r#"{"state":"roll_rate","term":"u_roll","coefficient":16.0}"#.to_string(),
            r#"{"state":"pitch_rate","term":"pitch","coefficient":-16.0}"#.to_string(),
            r#"{"state":"pitch_rate","term":"pitch_rate","coefficient":-3.0}"#.to_string(),
            r#"{"state":"pitch_rate","term":"u_pitch","coefficient":16.0}"#.to_string(),
            r#"{"state":"yaw_rate","term":"yaw_rate","coefficient":-2.0}"#.to_string(),
            r#"{"state":"yaw_rate","term":"u_yaw_rate","coefficient":2.0}"#.to_string(),
        ];
        if !extra.is_empty() {
            coefs.push(extra.to_string());
        }
        format!(
            r#"{{"format":"uavgen-model/1","kind":"sindy","name":"t",
            "library":["vx","vy","vz","u_vz","roll","roll_rate","u_roll","pitch","pitch_rate","u_pitch","yaw_rate","u_yaw_rate","vz^2"],
            "kinematic":[["x","vx"],["y","vy"],["z","vz"],["roll","roll_rate"],["pitch","pitch_rate"],["yaw","yaw_rate"]],
            "coefficients":[{}]}}"#,
            coefs.join(",")
        )
    }

    #[test]
    fn stable_linear_loops_pass() {
        let r = check(&model(&sindy("")), &HorizonCheck::default()).unwrap();
        assert!(r.passed(), "{}", r.summary());
        assert_eq!(r.trials, 257);
    }

    /// A heading term that is harmless near the logged heading and explodes away from it: the
    /// check over the whole circle catches it, the check within the logged yaw range does not.
    #[test]
    fn a_yaw_range_keeps_the_starts_within_the_logged_heading() {
        // roll_rate' = (7 − 10 cos(yaw)) roll_rate + …: damped (−3) near yaw 0, +17 at ±π. The yaw
        // rate is damped fast and its input barely acts, so yaw stays within 0.05 rad of its start.
        let json = sindy(r#"{"state":"roll_rate","term":"roll_rate*cos(yaw)","coefficient":-10.0}"#)
            .replace(r#""library":["#, r#""library":["roll_rate*cos(yaw)","#)
            .replace(
                r#"{"state":"roll_rate","term":"roll_rate","coefficient":-3.0}"#,
                r#"{"state":"roll_rate","term":"roll_rate","coefficient":7.0}"#,
            )
            .replace(
                r#"{"state":"yaw_rate","term":"u_yaw_rate","coefficient":2.0}"#,
                r#"{"state":"yaw_rate","term":"u_yaw_rate","coefficient":0.01}"#,
            )
            .replace(
                r#"{"state":"yaw_rate","term":"yaw_rate","coefficient":-2.0}"#,
                r#"{"state":"yaw_rate","term":"yaw_rate","coefficient":-20.0}"#,
            );
        let m = model(&json);
        let whole = check(&m, &HorizonCheck::default()).unwrap();
        assert!(!whole.passed(), "{}", whole.summary());
        let near = HorizonCheck {
            yaw: Some((-0.2, 0.2)),
            ..HorizonCheck::default()
        };
        let r = check(&m, &near).unwrap();
        assert!(r.passed(), "{}", r.summary());
    }

    #[test]
    fn a_quadratic_blow_up_is_caught() {
        // vz' = ... + 3 vz²: from vz = 4 m/s this reaches infinity within a fraction of a second.
        let m = model(&sindy(r#"{"state":"vz","term":"vz^2","coefficient":3.0}"#));
        let r = check(&m, &HorizonCheck::default()).unwrap();
        assert!(!r.passed());
        assert!(r.unbounded > 10, "{}", r.summary());
        assert!(r.summary().contains("left the bounds"));
        let f = r.first.unwrap();
        assert!(f.x0[8] > 0.0 || f.u[0] > 0.0, "{f:?}");
    }
}
