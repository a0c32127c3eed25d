//! The emulated DJI-SDK autopilot: commands u = [u_vz, u_roll, u_pitch, u_yaw_rate] → total
//! thrust and body torques, evaluated on the true state at the start of every RK4 substep (held
//! over the substep, as RotorPy calls its controller at every simulation step).
//!
//! - Vertical: T = m̂ (g + k_vz (u_vz − vz)) / (cos φ cos θ), cos φ cos θ = R₃₃ kept ≥ 0.3,
//!   T clamped to [0, T_max]; m̂ is `vehicle.mass` (the payload effect makes the truth heavier).
//! - Attitude (RotorPy's cmd_ctatt): R_des = Rz(ψ_sp + (kd_ψ/kp_ψ) u_yaw_rate) Ry(u_pitch) Rx(u_roll),
//!   e_R = ½ vee(R_desᵀ R − Rᵀ R_des), M = I (−kp ∘ e_R − kd ∘ ω) + ω × I ω, ψ_sp = ∫ u_yaw_rate.

use super::plant_file::PlantFile;
use super::rigid_body::{add, cross, mat_t_mat, mul, quat_to_matrix, rotation_zyx, BodyState, V3};

/// cos φ cos θ below this is taken as this in the tilt compensation.
pub const MIN_TILT_COS: f64 = 0.3;

#[derive(Clone, Debug)]
pub struct Autopilot {
    pub assumed_mass: f64,
    pub gravity: f64,
    pub k_vz: f64,
    pub kp: V3,
    pub kd: V3,
    pub yaw_feedforward: bool,
    pub inertia: V3,
    pub max_thrust: f64,
    pub limits: [f64; 4],
}

impl Autopilot {
    pub fn new(file: &PlantFile) -> Self {
        let a = &file.autopilot;
        Self {
            assumed_mass: file.vehicle.mass,
            gravity: file.vehicle.gravity,
            k_vz: a.k_vz,
            kp: a.kp_att,
            kd: a.kd_att,
            yaw_feedforward: a.yaw_rate_feedforward,
            inertia: file.vehicle.inertia,
            max_thrust: file.vehicle.max_thrust,
            limits: a.input_limits,
        }
    }

    /// The command as the autopilot accepts it: clamped to ±limits; a non-finite entry becomes 0
    /// (hover for that channel).
    pub fn clamp(&self, u: &[f64; 4]) -> [f64; 4] {
        let mut out = [0.0; 4];
        for i in 0..4 {
            out[i] = if u[i].is_finite() {
                u[i].clamp(-self.limits[i], self.limits[i])
            } else {
                0.0
            };
        }
        out
    }

    /// Thrust (N) and body torques (N m) for the (clamped, delayed) command `u` and the yaw
    /// set-point `psi_sp`.
    pub fn commands(&self, s: &BodyState, u: &[f64; 4], psi_sp: f64) -> (f64, V3) {
        let r = quat_to_matrix(s.q);
        let tilt = r[2][2].max(MIN_TILT_COS);
        let thrust =
            (self.assumed_mass * (self.gravity + self.k_vz * (u[0] - s.v[2])) / tilt).clamp(0.0, self.max_thrust);
        let lead = if self.yaw_feedforward && self.kp[2] > 0.0 {
            self.kd[2] / self.kp[2] * u[3]
        } else {
            0.0
        };
        let r_des = rotation_zyx(u[1], u[2], psi_sp + lead);
        let a = mat_t_mat(&r_des, &r);
        let b = mat_t_mat(&r, &r_des);
        let e = [
            0.5 * (a[2][1] - b[2][1]),
            0.5 * (a[0][2] - b[0][2]),
            0.5 * (a[1][0] - b[1][0]),
        ];
        let alpha = [
            -self.kp[0] * e[0] - self.kd[0] * s.w[0],
            -self.kp[1] * e[1] - self.kd[1] * s.w[1],
            -self.kp[2] * e[2] - self.kd[2] * s.w[2],
        ];
        let torque = add(mul(self.inertia, alpha), cross(s.w, mul(self.inertia, s.w)));
        (thrust, torque)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::rigid_body::quat_from_euler;

    fn autopilot() -> Autopilot {
        Autopilot {
            assumed_mass: 2.9,
            gravity: 9.81,
            k_vz: 2.5,
            kp: [144.0, 144.0, 6.0],
            kd: [19.2, 19.2, 4.9],
            yaw_feedforward: true,
            inertia: [0.05, 0.05, 0.085],
            max_thrust: 60.0,
            limits: crate::sim::plant_file::PAPER_INPUT_LIMITS,
        }
    }

    fn state(roll: f64, pitch: f64, yaw: f64, vz: f64) -> BodyState {
        BodyState {
            p: [0.0; 3],
            v: [0.0, 0.0, vz],
            q: quat_from_euler(roll, pitch, yaw),
            w: [0.0; 3],
            thrust: 0.0,
            torque: [0.0; 3],
        }
    }

    #[test]
    fn hover_thrust_and_tilt_compensation() {
        let a = autopilot();
        let (t, m) = a.commands(&state(0.0, 0.0, 0.0, 0.0), &[0.0; 4], 0.0);
        assert!((t - 2.9 * 9.81).abs() < 1e-12);
        assert!(m.iter().all(|x| x.abs() < 1e-12));
        let (t, _) = a.commands(&state(0.2, 0.1, 0.0, 0.4), &[1.0, 0.2, 0.1, 0.0], 0.0);
        let expected = 2.9 * (9.81 + 2.5 * 0.6) / (0.2f64.cos() * 0.1f64.cos());
        assert!((t - expected).abs() < 1e-9);
        // Saturation.
        let (t, _) = a.commands(&state(0.0, 0.0, 0.0, -20.0), &[5.0, 0.0, 0.0, 0.0], 0.0);
        assert_eq!(t, 60.0);
        let (t, _) = a.commands(&state(0.0, 0.0, 0.0, 20.0), &[-5.0, 0.0, 0.0, 0.0], 0.0);
        assert_eq!(t, 0.0);
    }

    #[test]
    fn small_attitude_error_gives_pd_torque() {
        let a = autopilot();
        // Level vehicle, roll command 0.01: torque ≈ Ix kp 0.01 about body x.
        let (_, m) = a.commands(&state(0.0, 0.0, 0.0, 0.0), &[0.0, 0.01, 0.0, 0.0], 0.0);
        assert!((m[0] - 0.05 * 144.0 * 0.01).abs() < 1e-5, "{m:?}");
        assert!(m[1].abs() < 1e-6 && m[2].abs() < 1e-6);
        let (_, m) = a.commands(&state(0.0, 0.0, 0.0, 0.0), &[0.0, 0.0, -0.01, 0.0], 0.0);
        assert!((m[1] + 0.05 * 144.0 * 0.01).abs() < 1e-5, "{m:?}");
        // Yaw set-point ahead by 0.01 rad.
        let (_, m) = a.commands(&state(0.0, 0.0, 1.0, 0.0), &[0.0; 4], 1.01);
        assert!((m[2] - 0.085 * 6.0 * 0.01).abs() < 1e-5, "{m:?}");
    }

    #[test]
    fn clamp_bounds_and_non_finite() {
        let a = autopilot();
        let u = a.clamp(&[9.0, -1.0, f64::NAN, 0.1]);
        assert_eq!(u, [5.0, -0.611, 0.0, 0.1]);
    }
}
