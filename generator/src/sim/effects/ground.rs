//! Ground effect (Cheeseman & Bennett 1955): at rotor height h above the ground (z = 0),
//! T_ige / T_oge = 1 / (1 − (R / 4h)²), capped at `max_ratio` (and taken as the cap for
//! h ≤ R/4, where the formula has its pole). h = z + rotor_height.

use crate::sim::plant_file::PlantFile;

#[derive(Clone, Debug)]
pub struct GroundEffectModel {
    radius: f64,
    max_ratio: f64,
    height: f64,
}

impl GroundEffectModel {
    pub fn new(file: &PlantFile) -> Option<Self> {
        file.effects.ground_effect.as_ref().map(|g| Self {
            radius: g.rotor_radius.unwrap_or(file.vehicle.rotor_radius),
            max_ratio: g.max_ratio,
            height: g.rotor_height,
        })
    }

    /// Thrust ratio in and out of ground effect at altitude z.
    pub fn ratio(&self, z: f64) -> f64 {
        let h = z + self.height;
        if h <= self.radius / 4.0 {
            return self.max_ratio;
        }
        let k = self.radius / (4.0 * h);
        (1.0 / (1.0 - k * k)).min(self.max_ratio)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cheeseman_bennett() {
        let g = GroundEffectModel {
            radius: 0.2,
            max_ratio: 1.5,
            height: 0.0,
        };
        // h = R: 1 / (1 − 1/16).
        assert!((g.ratio(0.2) - 16.0 / 15.0).abs() < 1e-12);
        assert!((g.ratio(100.0) - 1.0).abs() < 1e-6);
        assert_eq!(g.ratio(0.01), 1.5);
        assert_eq!(g.ratio(-1.0), 1.5);
    }
}
