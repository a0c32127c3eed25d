//! The operating envelope over which the substep count is chosen.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;

/// Symmetric bounds per state and input, looked up by the standard names of
/// `LOG_FORMAT.md`; other names get ±`default_bound`.
#[derive(Clone, Debug)]
pub struct Envelope {
    pub position: f64,
    pub tilt: f64,
    pub speed: f64,
    pub angular_rate: f64,
    /// |u| bounds: u_vz, u_roll, u_pitch, u_yaw_rate (the MPC's default bounds).
    pub inputs: [f64; 4],
    pub default_bound: f64,
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
            inputs: [5.0, 0.611, 0.611, 5.0 * PI / 6.0],
            default_bound: 1.0,
            samples: 512,
            seed: 0,
        }
    }
}

impl Envelope {
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

    /// The hover point (all zero) followed by `samples` uniform random points,
    /// each a vector over `names` (states then inputs). Deterministic.
    pub fn points(&self, names: &[String]) -> Vec<Vec<f64>> {
        let bounds: Vec<f64> = names.iter().map(|n| self.bound(n)).collect();
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut points = vec![vec![0.0; names.len()]];
        for _ in 0..self.samples {
            points.push(bounds.iter().map(|&b| rng.gen_range(-b..=b)).collect());
        }
        points
    }
}
