//! The operating envelope over which the substep count is chosen.

use crate::model::corrections::{DOT_LAGGED_SUFFIX, FLIGHT_TIME, LAGGED_SUFFIX};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// Bounds per state and input, looked up by the standard names of
/// `LOG_FORMAT.md`; other names get ±`default_bound`. The extra states of a
/// model's `corrections` have their own: `flight_time` ranges over
/// 0..`flight_time` s, `<input>_lagged` over the bounds of `<input>`, and `<state>_dot_lagged`
/// over ±`acceleration` (vx, vy, vz) or ±`angular_acceleration` (the rates).
/// The guess's trust region is this many times the envelope ([`Envelope::trust_bounds`]).
pub const TRUST_FACTOR: f64 = 2.0;
/// The plausibility envelope ([`Envelope::plausibility_bounds`]) is this many times the envelope
/// on velocities, body rates and lag states.
pub const PLAUSIBILITY_FACTOR: f64 = 10.0;
/// Largest plausible |roll|, |pitch|, rad (86°: the Euler angles are singular at π/2).
pub const PLAUSIBLE_TILT: f64 = 1.5;
/// Largest plausible |yaw|, rad (unwrapped: about 1600 turns; in f32 the angle is then still
/// resolved to 1e-3 rad).
pub const PLAUSIBLE_YAW: f64 = 1e4;
/// Largest plausible |x|, |y|, |z|, m.
pub const PLAUSIBLE_POSITION: f64 = 1e4;

#[derive(Clone, Debug)]
pub struct Envelope {
    pub position: f64,
    pub tilt: f64,
    pub speed: f64,
    pub angular_rate: f64,
    /// |v̇| (m/s²) and |ω̇| (rad/s²) bounds of the acceleration lag states.
    pub acceleration: f64,
    pub angular_acceleration: f64,
    /// |u| bounds: u_vz, u_roll, u_pitch, u_yaw_rate (the MPC's default bounds).
    pub inputs: [f64; 4],
    pub default_bound: f64,
    /// Upper end of `flight_time` (s); it starts at 0.
    pub flight_time: f64,
    pub samples: usize,
    pub seed: u64,
}

impl Default for Envelope {
    fn default() -> Self {
        Self {
            position: 10.0,
            tilt: 0.6,
            speed: 5.0,
            angular_rate: 3.0,
            acceleration: 10.0,
            angular_acceleration: 40.0,
            inputs: [5.0, 0.611, 0.611, 5.0 * PI / 6.0],
            default_bound: 1.0,
            flight_time: 600.0,
            samples: 512,
            seed: 0,
        }
    }
}

impl Envelope {
    /// The range [lo, hi] of the variable `name`.
    fn range(&self, name: &str) -> (f64, f64) {
        if name == FLIGHT_TIME {
            return (0.0, self.flight_time);
        }
        let b = if let Some(state) = name.strip_suffix(DOT_LAGGED_SUFFIX) {
            match state {
                "vx" | "vy" | "vz" => self.acceleration,
                _ => self.angular_acceleration,
            }
        } else {
            match name.strip_suffix(LAGGED_SUFFIX) {
                Some(input) => self.bound(input),
                None => self.bound(name),
            }
        };
        (-b, b)
    }

    fn bound(&self, name: &str) -> f64 {
        match name {
            "x" | "y" | "z" => self.position,
            "roll" | "pitch" => self.tilt,
            "yaw" => PI,
            "vx" | "vy" | "vz" => self.speed,
            "roll_rate" | "pitch_rate" | "yaw_rate" => self.angular_rate,
            "u_vz" => self.inputs[0],
            "u_roll" => self.inputs[1],
            "u_pitch" => self.inputs[2],
            "u_yaw_rate" => self.inputs[3],
            _ => self.default_bound,
        }
    }

    /// The trust region of the MPC's guess: |x̄ᵢ| ≤ bound for each state, `f64::INFINITY` where
    /// there is none. Twice the envelope on the attitude angles `roll`, `pitch` and on the body
    /// rates: there the models' rotational dynamics (Euler angles, singular at pitch = ±π/2) and
    /// the substep rule are trusted. When a guess leaves it, the MPC rolls the guess out with the
    /// model (docs/mpc.md, "The guess's trust region").
    pub fn trust_bounds(&self, states: &[String]) -> Vec<f64> {
        states
            .iter()
            .map(|name| match name.as_str() {
                "roll" | "pitch" => TRUST_FACTOR * self.tilt,
                "roll_rate" | "pitch_rate" | "yaw_rate" => TRUST_FACTOR * self.angular_rate,
                _ => f64::INFINITY,
            })
            .collect()
    }

    /// The plausibility envelope of the generated MPC's x₀ and reference (`ENVELOPE` of the
    /// generated crate; docs/mpc.md, "Plausibility"): |xᵢ| ≤ bound, `f64::INFINITY` where there is
    /// none. Positions 10 km, roll and pitch 1.5 rad (the Euler angles are singular at π/2), and
    /// [`PLAUSIBILITY_FACTOR`] times the envelope on velocities, body rates and the lag states;
    /// yaw ([`PLAUSIBLE_YAW`], unwrapped), `flight_time` and states of other names are unbounded.
    pub fn plausibility_bounds(&self, states: &[String]) -> Vec<f64> {
        states
            .iter()
            .map(|name| match name.as_str() {
                "x" | "y" | "z" => PLAUSIBLE_POSITION,
                "roll" | "pitch" => PLAUSIBLE_TILT,
                "yaw" => PLAUSIBLE_YAW,
                "vx" | "vy" | "vz" | "roll_rate" | "pitch_rate" | "yaw_rate" => PLAUSIBILITY_FACTOR * self.bound(name),
                n if n.ends_with(DOT_LAGGED_SUFFIX) || n.ends_with(LAGGED_SUFFIX) => {
                    PLAUSIBILITY_FACTOR * self.range(n).1
                }
                _ => f64::INFINITY,
            })
            .collect()
    }

    /// The plausibility range [lo, hi] of each state (`ENVELOPE_LO`, `ENVELOPE_HI` of the
    /// generated crate): the model file's declared envelope where it names the state, else
    /// ±[`Envelope::plausibility_bounds`] (±`f64::INFINITY` where there is none).
    pub fn plausibility_ranges(
        &self,
        states: &[String],
        declared: Option<&crate::model::DeclaredEnvelope>,
    ) -> Vec<(f64, f64)> {
        states
            .iter()
            .zip(self.plausibility_bounds(states))
            .map(|(name, b)| declared.and_then(|d| d.get(name)).unwrap_or((-b, b)))
            .collect()
    }

    /// The hover point (all zero) followed by `samples` uniform random points,
    /// each a vector over `names` (states then inputs). Deterministic.
    pub fn points(&self, names: &[String]) -> Vec<Vec<f64>> {
        let ranges: Vec<(f64, f64)> = names.iter().map(|n| self.range(n)).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut points = vec![vec![0.0; names.len()]];
        for _ in 0..self.samples {
            points.push(ranges.iter().map(|&(lo, hi)| rng.gen_range(lo..=hi)).collect());
        }
        points
    }
}
