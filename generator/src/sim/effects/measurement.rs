//! What the log and a controller see of the true state: white Gaussian `sensor_noise` per
//! group (pos on x y z, vel on vx vy vz, att on roll pitch yaw, rate on the Euler rates, volt on
//! the battery voltage), then `sample_hold`: with probability p a sample repeats the previous
//! sample's 12 states exactly (noise included; the voltage is always fresh), at most `max_run`
//! times in a row. With max_run = 1 the expected fraction of repeated samples is p / (1 + p).
//! The first sample after a reset is always fresh.

use crate::sim::plant_file::{PlantFile, SensorNoise};
use crate::sim::rng::{Random, Stream};

#[derive(Clone, Debug)]
pub struct Measurement {
    noise: Option<SensorNoise>,
    hold: Option<(f64, Option<usize>)>,
    noise_rng: Random,
    hold_rng: Random,
    last: Option<[f64; 12]>,
    run: usize,
}

impl Measurement {
    pub fn new(file: &PlantFile, seed: u64) -> Self {
        Self {
            noise: file.effects.sensor_noise.clone(),
            hold: file.effects.sample_hold.as_ref().map(|s| (s.probability, s.max_run)),
            noise_rng: Random::new(seed, Stream::SensorNoise, 0),
            hold_rng: Random::new(seed, Stream::SampleHold, 0),
            last: None,
            run: 0,
        }
    }

    /// Forget the previous sample (the next one is fresh).
    pub fn reset(&mut self) {
        self.last = None;
        self.run = 0;
    }

    /// Measure the true state and voltage: (states, voltage, whether the states were held).
    pub fn sample(&mut self, x: &[f64; 12], volt: f64) -> ([f64; 12], f64, bool) {
        let mut y = *x;
        let mut v = volt;
        if let Some(n) = &self.noise {
            for (i, yi) in y.iter_mut().enumerate() {
                let sigma = match i {
                    0..=2 => n.pos,
                    3..=5 => n.att,
                    6..=8 => n.vel,
                    _ => n.rate,
                };
                // Always draw, so the sequence does not depend on which sigmas are zero.
                *yi += sigma * self.noise_rng.normal();
            }
            v += n.volt * self.noise_rng.normal();
        }
        let mut held = false;
        if let (Some((p, max_run)), Some(last)) = (self.hold, self.last) {
            let draw = self.hold_rng.uniform();
            if draw < p && max_run.map_or(true, |m| self.run < m) {
                y = last;
                held = true;
            }
        }
        self.run = if held { self.run + 1 } else { 0 };
        self.last = Some(y);
        (y, v, held)
    }
}
