//! The rigid body: state (position, velocity, attitude quaternion, body rates), its time
//! derivative under a thrust along body z, body torques and external forces, and the
//! conversions to and from the log's ZYX Euler angles and Euler-angle rates.

pub type V3 = [f64; 3];
/// Rotation matrix, row-major: `m[i][j]`.
pub type M3 = [[f64; 3]; 3];

pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub fn mul(a: V3, b: V3) -> V3 {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}

pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn norm(a: V3) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

/// m a.
pub fn mat_vec(m: &M3, a: V3) -> V3 {
    [
        m[0][0] * a[0] + m[0][1] * a[1] + m[0][2] * a[2],
        m[1][0] * a[0] + m[1][1] * a[1] + m[1][2] * a[2],
        m[2][0] * a[0] + m[2][1] * a[1] + m[2][2] * a[2],
    ]
}

/// mᵀ a.
pub fn mat_t_vec(m: &M3, a: V3) -> V3 {
    [
        m[0][0] * a[0] + m[1][0] * a[1] + m[2][0] * a[2],
        m[0][1] * a[0] + m[1][1] * a[1] + m[2][1] * a[2],
        m[0][2] * a[0] + m[1][2] * a[1] + m[2][2] * a[2],
    ]
}

/// aᵀ b for matrices.
pub fn mat_t_mat(a: &M3, b: &M3) -> M3 {
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j];
        }
    }
    m
}

/// R = Rz(yaw) Ry(pitch) Rx(roll): body to inertial (ENU).
pub fn rotation_zyx(roll: f64, pitch: f64, yaw: f64) -> M3 {
    let (sf, cf) = roll.sin_cos();
    let (st, ct) = pitch.sin_cos();
    let (sp, cp) = yaw.sin_cos();
    [
        [cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf],
        [sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf],
        [-st, ct * sf, ct * cf],
    ]
}

/// ZYX Euler angles (roll, pitch, yaw) of a rotation matrix; yaw in (−π, π].
pub fn euler_zyx(r: &M3) -> V3 {
    let pitch = (-r[2][0]).clamp(-1.0, 1.0).asin();
    [r[2][1].atan2(r[2][2]), pitch, r[1][0].atan2(r[0][0])]
}

/// Unit quaternion [w, x, y, z].
pub type Quat = [f64; 4];

pub fn quat_from_euler(roll: f64, pitch: f64, yaw: f64) -> Quat {
    let (sf, cf) = (roll / 2.0).sin_cos();
    let (st, ct) = (pitch / 2.0).sin_cos();
    let (sp, cp) = (yaw / 2.0).sin_cos();
    [
        cf * ct * cp + sf * st * sp,
        sf * ct * cp - cf * st * sp,
        cf * st * cp + sf * ct * sp,
        cf * ct * sp - sf * st * cp,
    ]
}

pub fn quat_to_matrix(q: Quat) -> M3 {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// q / |q| (the identity for a zero or non-finite q).
pub fn quat_normalize(q: Quat) -> Quat {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if n.is_finite() && n > 0.0 {
        [q[0] / n, q[1] / n, q[2] / n, q[3] / n]
    } else {
        [1.0, 0.0, 0.0, 0.0]
    }
}

/// q̇ = ½ q ⊗ (0, ω) for body rates ω.
pub fn quat_derivative(q: Quat, w: V3) -> Quat {
    let [qw, qx, qy, qz] = q;
    [
        0.5 * (-qx * w[0] - qy * w[1] - qz * w[2]),
        0.5 * (qw * w[0] + qy * w[2] - qz * w[1]),
        0.5 * (qw * w[1] - qx * w[2] + qz * w[0]),
        0.5 * (qw * w[2] + qx * w[1] - qy * w[0]),
    ]
}

/// Body rates from Euler-angle rates: ω = W(φ, θ) η̇, W = [[1, 0, −sθ], [0, cφ, sφ cθ], [0, −sφ, cφ cθ]].
pub fn body_rates_from_euler_rates(roll: f64, pitch: f64, rates: V3) -> V3 {
    let (sf, cf) = roll.sin_cos();
    let (st, ct) = pitch.sin_cos();
    [
        rates[0] - st * rates[2],
        cf * rates[1] + sf * ct * rates[2],
        -sf * rates[1] + cf * ct * rates[2],
    ]
}

/// Euler-angle rates from body rates: η̇ = W⁻¹ ω (cos θ kept away from 0).
pub fn euler_rates_from_body_rates(roll: f64, pitch: f64, w: V3) -> V3 {
    let (sf, cf) = roll.sin_cos();
    let ct = pitch.cos();
    let ct = if ct.abs() < 1e-6 { 1e-6_f64.copysign(ct) } else { ct };
    let tt = pitch.sin() / ct;
    let s = w[1] * sf + w[2] * cf;
    [w[0] + s * tt, w[1] * cf - w[2] * sf, s / ct]
}

/// The integrated state of the vehicle and its actuators.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyState {
    /// Inertial ENU position, m.
    pub p: V3,
    /// Inertial velocity, m/s.
    pub v: V3,
    /// Attitude, body to inertial.
    pub q: Quat,
    /// Body rates, rad/s.
    pub w: V3,
    /// Actual total thrust (N) and body torques (N m) before the battery and ground-effect
    /// factors; they follow the commands through the motor lag, or equal them without it.
    pub thrust: f64,
    pub torque: V3,
}

/// Forces and moments held over one RK4 substep.
#[derive(Clone, Copy, Debug)]
pub struct Inputs {
    /// Commanded thrust and torques (targets of the motor lag).
    pub thrust_cmd: f64,
    pub torque_cmd: V3,
    /// Motor time constant; `None`: actuators follow the commands instantly.
    pub motor_tau: Option<f64>,
    /// Multiplies the thrust (battery × ground effect).
    pub thrust_factor: f64,
    /// Multiplies the torques (battery).
    pub torque_factor: f64,
    /// True mass, kg.
    pub mass: f64,
    pub inertia: V3,
    pub gravity: f64,
}

/// An external force (inertial frame, N) as a function of the state.
pub trait ExternalForce {
    fn force(&self, p: V3, v: V3, r: &M3) -> V3;
}

/// ẋ of the body and actuator states.
pub fn derivative(s: &BodyState, inp: &Inputs, ext: &impl ExternalForce) -> BodyState {
    let r = quat_to_matrix(quat_normalize(s.q));
    let (thrust, torque, thrust_dot, torque_dot) = match inp.motor_tau {
        Some(tau) => (
            s.thrust,
            s.torque,
            (inp.thrust_cmd - s.thrust) / tau,
            scale(sub(inp.torque_cmd, s.torque), 1.0 / tau),
        ),
        None => (inp.thrust_cmd, inp.torque_cmd, 0.0, [0.0; 3]),
    };
    let t = thrust * inp.thrust_factor;
    let body_z = [r[0][2], r[1][2], r[2][2]];
    let f = add(scale(body_z, t), ext.force(s.p, s.v, &r));
    let acc = [f[0] / inp.mass, f[1] / inp.mass, f[2] / inp.mass - inp.gravity];
    let iw = mul(inp.inertia, s.w);
    let m = sub(scale(torque, inp.torque_factor), cross(s.w, iw));
    let wdot = [m[0] / inp.inertia[0], m[1] / inp.inertia[1], m[2] / inp.inertia[2]];
    BodyState {
        p: s.v,
        v: acc,
        q: quat_derivative(s.q, s.w),
        w: wdot,
        thrust: thrust_dot,
        torque: torque_dot,
    }
}

/// s + h k.
pub fn axpy(s: &BodyState, h: f64, k: &BodyState) -> BodyState {
    BodyState {
        p: add(s.p, scale(k.p, h)),
        v: add(s.v, scale(k.v, h)),
        q: [
            s.q[0] + h * k.q[0],
            s.q[1] + h * k.q[1],
            s.q[2] + h * k.q[2],
            s.q[3] + h * k.q[3],
        ],
        w: add(s.w, scale(k.w, h)),
        thrust: s.thrust + h * k.thrust,
        torque: add(s.torque, scale(k.torque, h)),
    }
}

/// One classic RK4 step of length h with the inputs held; the quaternion is renormalised.
pub fn rk4(s: &BodyState, h: f64, inp: &Inputs, ext: &impl ExternalForce) -> BodyState {
    let k1 = derivative(s, inp, ext);
    let k2 = derivative(&axpy(s, h / 2.0, &k1), inp, ext);
    let k3 = derivative(&axpy(s, h / 2.0, &k2), inp, ext);
    let k4 = derivative(&axpy(s, h, &k3), inp, ext);
    let mut sum = axpy(&axpy(&axpy(&k1, 2.0, &k2), 2.0, &k3), 1.0, &k4);
    sum = axpy(s, h / 6.0, &sum);
    sum.q = quat_normalize(sum.q);
    if inp.motor_tau.is_none() {
        sum.thrust = inp.thrust_cmd;
        sum.torque = inp.torque_cmd;
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    struct NoForce;
    impl ExternalForce for NoForce {
        fn force(&self, _: V3, _: V3, _: &M3) -> V3 {
            [0.0; 3]
        }
    }

    #[test]
    fn euler_round_trips() {
        for (f, t, p) in [(0.1, -0.2, 0.3), (-0.5, 0.4, 3.0), (0.0, 0.0, -2.5)] {
            let r = rotation_zyx(f, t, p);
            let e = euler_zyx(&r);
            assert!((e[0] - f).abs() < 1e-12 && (e[1] - t).abs() < 1e-12 && (e[2] - p).abs() < 1e-12);
            let rq = quat_to_matrix(quat_from_euler(f, t, p));
            for i in 0..3 {
                for j in 0..3 {
                    assert!((rq[i][j] - r[i][j]).abs() < 1e-12);
                }
            }
            let rates = [0.3, -0.7, 1.1];
            let w = body_rates_from_euler_rates(f, t, rates);
            let back = euler_rates_from_body_rates(f, t, w);
            for i in 0..3 {
                assert!((back[i] - rates[i]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn free_fall_and_torque_free_spin() {
        let s = BodyState {
            p: [0.0, 0.0, 10.0],
            v: [1.0, 0.0, 0.0],
            q: quat_from_euler(0.0, 0.0, 0.0),
            w: [0.0, 0.0, 1.0],
            thrust: 0.0,
            torque: [0.0; 3],
        };
        let inp = Inputs {
            thrust_cmd: 0.0,
            torque_cmd: [0.0; 3],
            motor_tau: None,
            thrust_factor: 1.0,
            torque_factor: 1.0,
            mass: 2.0,
            inertia: [0.05, 0.05, 0.085],
            gravity: 9.81,
        };
        let mut x = s;
        for _ in 0..100 {
            x = rk4(&x, 0.01, &inp, &NoForce);
        }
        // z = 10 − g t²/2 at t = 1, x = 1, yaw = 1 rad.
        assert!((x.p[2] - (10.0 - 9.81 / 2.0)).abs() < 1e-9);
        assert!((x.p[0] - 1.0).abs() < 1e-12);
        let e = euler_zyx(&quat_to_matrix(x.q));
        assert!((e[2] - 1.0).abs() < 1e-9, "{e:?}");
    }
}
