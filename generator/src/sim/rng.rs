//! Seeded random streams. Every random process of the simulator draws from its own ChaCha8
//! stream of the one seed, so turning an effect on or off never changes the random numbers of
//! another (the sensor noise of a run with wind equals that of the same run without).

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The stream of each random process.
#[derive(Clone, Copy, Debug)]
pub enum Stream {
    SensorNoise = 1,
    SampleHold = 2,
    Turbulence = 3,
    /// The excitation and disturbances of the flight profiles.
    Profile = 4,
}

/// A generator of uniform and standard normal numbers.
#[derive(Clone, Debug)]
pub struct Random {
    rng: ChaCha8Rng,
}

impl Random {
    /// `seed` and `stream` select the sequence; `index` separates several uses of one stream
    /// (e.g. one per segment).
    pub fn new(seed: u64, stream: Stream, index: u64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(((stream as u64) << 32) | (index & 0xffff_ffff));
        Self { rng }
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.rng.gen::<f64>()
    }

    /// Uniform in [a, b).
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.uniform()
    }

    /// Standard normal (Box-Muller; one value per pair of uniforms).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform(); // (0, 1]
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_has_unit_variance_and_streams_differ() {
        let mut r = Random::new(7, Stream::SensorNoise, 0);
        let n = 200_000;
        let xs: Vec<f64> = (0..n).map(|_| r.normal()).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.01 && (var - 1.0).abs() < 0.01, "{mean} {var}");
        let a = Random::new(7, Stream::SensorNoise, 0).uniform();
        let b = Random::new(7, Stream::SampleHold, 0).uniform();
        let c = Random::new(8, Stream::SensorNoise, 0).uniform();
        assert!(a != b && a != c);
        assert_eq!(a, Random::new(7, Stream::SensorNoise, 0).uniform());
    }
}
