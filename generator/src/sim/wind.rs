//! Wind: a steady vector plus Dryden turbulence.
//!
//! The turbulence uses the first-order (longitudinal) Dryden form on each inertial axis: a
//! Gauss-Markov process with standard deviation σᵢ and correlation time L / V, discretised
//! exactly over a step h: wᵢ ← a wᵢ + σᵢ √(1 − a²) n, a = exp(−V h / L), n standard normal.
//! V is the airspeed relative to the steady wind, at least [`MIN_AIRSPEED`] so that a hovering
//! vehicle still meets gusts. The process starts in its stationary distribution.

use super::plant_file::Wind;
use super::rigid_body::{add, norm, sub, V3};
use super::rng::{Random, Stream};

/// m/s: the smallest speed through the turbulence field.
pub const MIN_AIRSPEED: f64 = 1.0;

#[derive(Clone, Debug)]
pub struct WindField {
    steady: V3,
    sigma: V3,
    length: f64,
    gust: V3,
    rng: Random,
}

impl WindField {
    pub fn new(wind: &Wind, seed: u64) -> Self {
        let mut rng = Random::new(seed, Stream::Turbulence, 0);
        let (sigma, length) = match &wind.turbulence {
            Some(t) => (t.sigma, t.length_scale),
            None => ([0.0; 3], 1.0),
        };
        let gust = [
            sigma[0] * rng.normal(),
            sigma[1] * rng.normal(),
            sigma[2] * rng.normal(),
        ];
        Self {
            steady: wind.velocity,
            sigma,
            length,
            gust,
            rng,
        }
    }

    /// The wind now (inertial, m/s).
    pub fn velocity(&self) -> V3 {
        add(self.steady, self.gust)
    }

    /// Advance the turbulence by h seconds for a vehicle moving at `v`.
    pub fn advance(&mut self, h: f64, v: V3) {
        if self.sigma.iter().all(|s| *s == 0.0) {
            return;
        }
        let speed = norm(sub(v, self.steady)).max(MIN_AIRSPEED);
        let a = (-speed * h / self.length).exp();
        let b = (1.0 - a * a).max(0.0).sqrt();
        for i in 0..3 {
            self.gust[i] = a * self.gust[i] + self.sigma[i] * b * self.rng.normal();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::plant_file::Turbulence;

    #[test]
    fn turbulence_has_the_set_sigma_and_correlation() {
        let wind = Wind {
            velocity: [2.0, 0.0, 0.0],
            turbulence: Some(Turbulence {
                sigma: [0.5, 0.5, 0.2],
                length_scale: 10.0,
            }),
            direct_coefficient: [0.0; 3],
        };
        let mut f = WindField::new(&wind, 3);
        let h = 0.01;
        let n = 400_000;
        let (mut s, mut s2, mut lag) = (0.0, 0.0, 0.0);
        let mut prev = f.velocity()[0] - 2.0;
        for _ in 0..n {
            // Hovering in a 2 m/s wind: V = 2 m/s, correlation time L / V = 5 s.
            f.advance(h, [0.0; 3]);
            let g = f.velocity()[0] - 2.0;
            s += g;
            s2 += g * g;
            lag += g * prev;
            prev = g;
        }
        let var = s2 / n as f64 - (s / n as f64).powi(2);
        assert!((var.sqrt() - 0.5).abs() < 0.05, "sigma {}", var.sqrt());
        let rho = lag / s2;
        assert!((rho - (-2.0 * h / 10.0f64).exp()).abs() < 1e-3, "rho {rho}");
    }
}
