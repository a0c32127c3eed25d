//! The pilot: a position loop that turns a reference (position, velocity, acceleration, yaw)
//! into autopilot commands, from the *measured* state (noise and stale samples included, as a
//! real pilot or MPC would see them).
//!
//! Horizontal: a = a_ref + kp (p_ref − p) + kd (v_ref − v), rotated into the yaw frame
//! (a_f = Rz(ψ)ᵀ a), then the tilt that makes the autopilot's thrust (which holds the weight)
//! produce it: pitch = atan(a_f,x / g), roll = atan(−a_f,y cos(pitch) / g), both clamped to
//! ±`max_tilt`. Vertical: u_vz = vz_ref + kz (z_ref − z), clamped to ±`max_vz`. Yaw:
//! u_yaw_rate = yaw_rate_ref + kψ wrap(ψ_ref − ψ).

use super::plant::wrap_angle;

/// A reference sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Reference {
    pub p: [f64; 3],
    pub v: [f64; 3],
    pub a: [f64; 3],
    pub yaw: f64,
    pub yaw_rate: f64,
}

/// Gains and limits of the position loop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OuterLoop {
    /// 1/s².
    pub kp: f64,
    /// 1/s.
    pub kd: f64,
    /// 1/s.
    pub kz: f64,
    /// 1/s.
    pub k_yaw: f64,
    /// rad.
    pub max_tilt: f64,
    /// m/s.
    pub max_vz: f64,
    pub gravity: f64,
}

impl OuterLoop {
    /// The trajectory-tracking loop: ωn ≈ 1.2 rad/s, ζ ≈ 0.9 horizontally.
    pub fn tracking(gravity: f64) -> Self {
        Self {
            kp: 1.5,
            kd: 2.2,
            kz: 1.5,
            k_yaw: 1.0,
            max_tilt: 0.5,
            max_vz: 3.0,
            gravity,
        }
    }

    /// The horizontal acceleration (inertial) the loop asks for.
    pub fn acceleration(&self, x: &[f64; 12], r: &Reference) -> [f64; 2] {
        [
            r.a[0] + self.kp * (r.p[0] - x[0]) + self.kd * (r.v[0] - x[6]),
            r.a[1] + self.kp * (r.p[1] - x[1]) + self.kd * (r.v[1] - x[7]),
        ]
    }

    /// [roll, pitch] that produce the horizontal acceleration `a` at yaw ψ, clamped.
    pub fn tilt_for(&self, a: [f64; 2], yaw: f64) -> [f64; 2] {
        let (s, c) = yaw.sin_cos();
        let ax = c * a[0] + s * a[1];
        let ay = -s * a[0] + c * a[1];
        let pitch = (ax / self.gravity).atan().clamp(-self.max_tilt, self.max_tilt);
        let roll = (-ay * pitch.cos() / self.gravity)
            .atan()
            .clamp(-self.max_tilt, self.max_tilt);
        [roll, pitch]
    }

    /// The command for the measured state `x` and the reference `r`.
    pub fn command(&self, x: &[f64; 12], r: &Reference) -> [f64; 4] {
        let [roll, pitch] = self.tilt_for(self.acceleration(x, r), x[5]);
        let vz = (r.v[2] + self.kz * (r.p[2] - x[2])).clamp(-self.max_vz, self.max_vz);
        let yaw_rate = r.yaw_rate + self.k_yaw * wrap_angle(r.yaw - x[5]);
        [vz, roll, pitch, yaw_rate]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tilt_direction_follows_yaw() {
        let l = OuterLoop::tracking(9.81);
        // Accelerate along +x at yaw 0: pitch forward (positive), no roll.
        let [roll, pitch] = l.tilt_for([1.0, 0.0], 0.0);
        assert!(pitch > 0.09 && roll.abs() < 1e-12);
        // Along +y at yaw 0: negative roll (body z tilts to +y).
        let [roll, pitch] = l.tilt_for([0.0, 1.0], 0.0);
        assert!(roll < -0.09 && pitch.abs() < 1e-12);
        // Along +y at yaw 90°: the nose points +y, so pitch forward.
        let [roll, pitch] = l.tilt_for([0.0, 1.0], std::f64::consts::FRAC_PI_2);
        assert!(pitch > 0.09 && roll.abs() < 1e-12);
    }
}
