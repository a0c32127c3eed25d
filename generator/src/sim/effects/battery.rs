//! The battery: V(t) = max(V0 − rate t, V_min) with the `battery_sag` effect (V_min default
//! 0.8 V0), else V(t) = V0. With the effect the thrust and torques per command scale by
//! (V / V0)^exponent (exponent default 2: rotor thrust ∝ ω², ω ∝ V at a fixed command).

use crate::sim::plant_file::PlantFile;

/// Default V_min / V0.
pub const DEFAULT_MIN_FRACTION: f64 = 0.8;

#[derive(Clone, Debug)]
pub struct Battery {
    v0: f64,
    rate: f64,
    min: f64,
    exponent: f64,
}

impl Battery {
    pub fn new(file: &PlantFile) -> Self {
        let v0 = file.vehicle.battery_voltage;
        match &file.effects.battery_sag {
            Some(b) => Self {
                v0,
                rate: b.rate,
                min: b.min_voltage.unwrap_or(DEFAULT_MIN_FRACTION * v0),
                exponent: b.exponent,
            },
            None => Self {
                v0,
                rate: 0.0,
                min: v0,
                exponent: 0.0,
            },
        }
    }

    /// Volts at flight time t (s).
    pub fn voltage(&self, t: f64) -> f64 {
        (self.v0 - self.rate * t.max(0.0)).max(self.min)
    }

    /// Thrust (and torque) per command relative to a full battery.
    pub fn factor(&self, t: f64) -> f64 {
        (self.voltage(t) / self.v0).powf(self.exponent)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sag_law() {
        let text = crate::sim::plant_file::tests_support::NOMINAL.replacen(
            "\"substeps\": 7 }",
            "\"substeps\": 7 }, \"effects\": { \"battery_sag\": { \"rate\": 0.01 } }",
            1,
        );
        let f = PlantFile::parse(&text, "b.json").unwrap();
        let b = Battery::new(&f);
        assert_eq!(b.voltage(0.0), 24.6);
        assert!((b.voltage(100.0) - 23.6).abs() < 1e-12);
        assert!((b.factor(100.0) - (23.6f64 / 24.6).powi(2)).abs() < 1e-12);
        assert!((b.voltage(1e6) - 0.8 * 24.6).abs() < 1e-12);
        let nominal = PlantFile::parse(crate::sim::plant_file::tests_support::NOMINAL, "n.json").unwrap();
        let b = Battery::new(&nominal);
        assert_eq!((b.voltage(1e3), b.factor(1e3)), (24.6, 1.0));
    }
}
