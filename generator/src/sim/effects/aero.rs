//! Aerodynamic forces on the airspeed v_a = v − w (inertial), expressed in the body frame
//! (v_a,b = Rᵀ v_a):
//!
//! - `linear_drag` (rotor drag / H-force): F_b = −m₀ diag(d) v_a,b, d in 1/s;
//! - `quadratic_drag` (parasitic): F_b = −m₀ |v_a| diag(c) v_a,b, c in 1/m;
//! - the wind's `direct_coefficient` k: F = m₀ diag(k) w (inertial), independent of v.
//!
//! m₀ is `vehicle.mass` (the airframe; a payload does not change the drag force).

use crate::sim::plant_file::Effects;
use crate::sim::rigid_body::{add, mat_t_vec, mat_vec, mul, norm, scale, sub, ExternalForce, M3, V3};

#[derive(Clone, Debug, Default)]
pub struct Aero {
    /// m₀ d, N s/m per body axis.
    linear: Option<V3>,
    /// m₀ c, N s²/m² per body axis.
    quadratic: Option<V3>,
    /// m₀ k, N s/m per inertial axis.
    direct: V3,
}

impl Aero {
    pub fn new(effects: &Effects, airframe_mass: f64) -> Self {
        Self {
            linear: effects
                .linear_drag
                .as_ref()
                .map(|d| scale(d.coefficients, airframe_mass)),
            quadratic: effects
                .quadratic_drag
                .as_ref()
                .map(|d| scale(d.coefficients, airframe_mass)),
            direct: effects
                .wind
                .as_ref()
                .map(|w| scale(w.direct_coefficient, airframe_mass))
                .unwrap_or([0.0; 3]),
        }
    }

    /// The force (inertial, N) at velocity `v` with attitude `r` in the wind `wind`.
    pub fn force(&self, v: V3, r: &M3, wind: V3) -> V3 {
        let mut f = mul(self.direct, wind);
        if self.linear.is_none() && self.quadratic.is_none() {
            return f;
        }
        let va = mat_t_vec(r, sub(v, wind));
        let mut fb = [0.0; 3];
        if let Some(d) = self.linear {
            fb = sub(fb, mul(d, va));
        }
        if let Some(c) = self.quadratic {
            fb = sub(fb, scale(mul(c, va), norm(va)));
        }
        f = add(f, mat_vec(r, fb));
        f
    }
}

/// [`Aero`] with the wind held over one RK4 substep.
pub struct AeroForce<'a> {
    pub aero: &'a Aero,
    pub wind: V3,
}

impl ExternalForce for AeroForce<'_> {
    fn force(&self, _p: V3, v: V3, r: &M3) -> V3 {
        self.aero.force(v, r, self.wind)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::plant_file::{LinearDrag, QuadraticDrag, Wind};
    use crate::sim::rigid_body::rotation_zyx;

    #[test]
    fn drag_opposes_airspeed_in_body_axes() {
        let effects = Effects {
            linear_drag: Some(LinearDrag {
                coefficients: [0.3, 0.3, 0.5],
            }),
            quadratic_drag: Some(QuadraticDrag {
                coefficients: [0.01, 0.01, 0.02],
            }),
            wind: Some(Wind {
                velocity: [0.0; 3],
                turbulence: None,
                direct_coefficient: [0.1, 0.1, 0.0],
            }),
            ..Effects::default()
        };
        let a = Aero::new(&effects, 2.0);
        let level = rotation_zyx(0.0, 0.0, 0.0);
        let f = a.force([2.0, 0.0, 0.0], &level, [0.0; 3]);
        assert!((f[0] - -(2.0 * 0.3 * 2.0 + 2.0 * 0.01 * 2.0 * 2.0)).abs() < 1e-12);
        assert!(f[1].abs() < 1e-12 && f[2].abs() < 1e-12);
        // Yawed by 90°: body x is inertial y; moving along inertial y drags along body x.
        let yawed = rotation_zyx(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let f = a.force([0.0, 1.0, 0.0], &yawed, [0.0; 3]);
        assert!((f[1] + 0.62).abs() < 1e-12 && f[0].abs() < 1e-12, "{f:?}");
        // Standing in a 3 m/s wind: drag pushes downwind, plus the direct force.
        let f = a.force([0.0; 3], &level, [3.0, 0.0, 0.0]);
        let expected = 2.0 * 0.3 * 3.0 + 2.0 * 0.01 * 9.0 + 2.0 * 0.1 * 3.0;
        assert!((f[0] - expected).abs() < 1e-12, "{f:?}");
    }
}
