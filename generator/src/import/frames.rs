//! Frame and angle conventions shared by every importer (docs/import.md, "Frames").
//!
//! The log contract (docs/log-format.md) is inertial ENU (x east, y north, z up) and body FLU
//! (x forward, y left, z up), attitude as ZYX Euler angles with R = Rz(yaw) Ry(pitch) Rx(roll)
//! mapping body to inertial vectors, and `roll_rate`, `pitch_rate`, `yaw_rate` the time
//! derivatives of those angles (not body rates). PX4 and ArduPilot log inertial NED and body FRD;
//! ROS (REP 103) uses ENU and FLU.
//!
//! NED → ENU swaps the first two axes and negates the third (`T`); FRD → FLU negates y and z
//! (`F`). Both are their own inverses, so a body-to-NED rotation R becomes the body(FLU)-to-ENU
//! rotation `T R F`. For ZYX Euler angles this is roll' = roll, pitch' = −pitch,
//! yaw' = π/2 − yaw.

use std::f64::consts::FRAC_PI_2;

/// A 3×3 matrix, row major.
pub type Mat3 = [[f64; 3]; 3];

/// An inertial frame convention.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Inertial {
    /// x east, y north, z up (ROS REP 103, the log contract).
    Enu,
    /// x north, y east, z down (PX4, ArduPilot, DJI internals).
    Ned,
}

/// A body frame convention.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Body {
    /// x forward, y left, z up (ROS REP 103, the log contract).
    Flu,
    /// x forward, y right, z down (PX4, ArduPilot).
    Frd,
}

/// NED ↔ ENU for vectors (its own inverse).
pub fn ned_to_enu(v: [f64; 3]) -> [f64; 3] {
    [v[1], v[0], -v[2]]
}

/// FRD ↔ FLU for vectors (its own inverse).
pub fn frd_to_flu(v: [f64; 3]) -> [f64; 3] {
    [v[0], -v[1], -v[2]]
}

/// An inertial vector in `frame` as ENU.
pub fn inertial_to_enu(v: [f64; 3], frame: Inertial) -> [f64; 3] {
    match frame {
        Inertial::Enu => v,
        Inertial::Ned => ned_to_enu(v),
    }
}

/// A body vector in `frame` as FLU.
pub fn body_to_flu(v: [f64; 3], frame: Body) -> [f64; 3] {
    match frame {
        Body::Flu => v,
        Body::Frd => frd_to_flu(v),
    }
}

/// The rotation matrix of a unit quaternion `[w, x, y, z]` (Hamilton convention, rotating
/// body-frame vectors into the inertial frame). The quaternion is normalised first; `None` if its
/// norm is zero or not finite.
pub fn quat_to_matrix(q: [f64; 4]) -> Option<Mat3> {
    let n = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    if !(n.is_finite() && n > 1e-12) {
        return None;
    }
    // The simulator's rigid-body convention is this one (Hamilton, body → inertial).
    Some(crate::sim::rigid_body::quat_to_matrix([
        q[0] / n,
        q[1] / n,
        q[2] / n,
        q[3] / n,
    ]))
}

/// A unit quaternion `[w, x, y, z]` of a rotation matrix (Shepperd's method; w ≥ 0).
pub fn matrix_to_quat(r: &Mat3) -> [f64; 4] {
    let trace = r[0][0] + r[1][1] + r[2][2];
    let q = if trace > 0.0 {
        let s = 2.0 * (1.0 + trace).sqrt();
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = 2.0 * (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt();
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = 2.0 * (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt();
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = 2.0 * (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt();
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    if q[0] < 0.0 {
        [-q[0], -q[1], -q[2], -q[3]]
    } else {
        q
    }
}

/// R = Rz(yaw) Ry(pitch) Rx(roll).
pub fn euler_to_matrix(e: [f64; 3]) -> Mat3 {
    let (sr, cr) = e[0].sin_cos();
    let (sp, cp) = e[1].sin_cos();
    let (sy, cy) = e[2].sin_cos();
    [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
}

/// ZYX Euler angles `[roll, pitch, yaw]` of R = Rz(yaw) Ry(pitch) Rx(roll); roll and yaw in
/// (−π, π], pitch in [−π/2, π/2]. Pitch from atan2 (not asin) so it keeps full precision near ±π/2.
pub fn matrix_to_euler(r: &Mat3) -> [f64; 3] {
    let roll = r[2][1].atan2(r[2][2]);
    let pitch = (-r[2][0]).atan2(r[0][0].hypot(r[1][0]));
    let yaw = r[1][0].atan2(r[0][0]);
    [roll, pitch, yaw]
}

fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            out[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

const T_NED_ENU: Mat3 = [[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]];
const F_FRD_FLU: Mat3 = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];

/// A body-to-inertial rotation given in (`inertial`, `body`) conventions as the body(FLU)-to-ENU
/// rotation of the log contract.
pub fn rotation_to_enu_flu(r: &Mat3, inertial: Inertial, body: Body) -> Mat3 {
    let left = match inertial {
        Inertial::Enu => *r,
        Inertial::Ned => mul(&T_NED_ENU, r),
    };
    match body {
        Body::Flu => left,
        Body::Frd => mul(&left, &F_FRD_FLU),
    }
}

/// The inverse of [`rotation_to_enu_flu`]: an ENU/FLU rotation in (`inertial`, `body`).
pub fn rotation_from_enu_flu(r: &Mat3, inertial: Inertial, body: Body) -> Mat3 {
    // T and F are involutions, so the same products undo themselves.
    rotation_to_enu_flu(r, inertial, body)
}

/// ZYX Euler angles (ENU/FLU) of a quaternion given in (`inertial`, `body`) conventions.
pub fn quat_to_euler_enu(q: [f64; 4], inertial: Inertial, body: Body) -> Option<[f64; 3]> {
    let r = quat_to_matrix(q)?;
    Some(matrix_to_euler(&rotation_to_enu_flu(&r, inertial, body)))
}

/// ZYX Euler angles (ENU/FLU) of ZYX Euler angles given in (`inertial`, `body`) conventions.
/// For NED/FRD this is (roll, −pitch, π/2 − yaw) with yaw wrapped to (−π, π].
pub fn euler_to_euler_enu(e: [f64; 3], inertial: Inertial, body: Body) -> [f64; 3] {
    if inertial == Inertial::Enu && body == Body::Flu {
        return e;
    }
    matrix_to_euler(&rotation_to_enu_flu(&euler_to_matrix(e), inertial, body))
}

/// The yaw of a NED heading (0 north, clockwise positive) as ENU yaw (0 east, counter-clockwise).
pub fn ned_yaw_to_enu(yaw: f64) -> f64 {
    FRAC_PI_2 - yaw
}

/// Body angular rates (p, q, r) in FLU → the time derivatives of ZYX Euler angles
/// `[roll_rate, pitch_rate, yaw_rate]` at attitude `euler`. Singular at pitch ±π/2 (gimbal lock):
/// `None` when |cos pitch| < 1e-9.
pub fn body_rates_to_euler_rates(w: [f64; 3], euler: [f64; 3]) -> Option<[f64; 3]> {
    let (sr, cr) = euler[0].sin_cos();
    let (sp, cp) = euler[1].sin_cos();
    if cp.abs() < 1e-9 {
        return None;
    }
    let [p, q, r] = w;
    Some([p + (sr * q + cr * r) * sp / cp, cr * q - sr * r, (sr * q + cr * r) / cp])
}

/// The inverse of [`body_rates_to_euler_rates`]: Euler-angle rates → body rates (FLU).
pub fn euler_rates_to_body_rates(d: [f64; 3], euler: [f64; 3]) -> [f64; 3] {
    let (sr, cr) = euler[0].sin_cos();
    let (sp, cp) = euler[1].sin_cos();
    [
        d[0] - sp * d[2],
        cr * d[1] + sr * cp * d[2],
        -sr * d[1] + cr * cp * d[2],
    ]
}

/// Wrap an angle to (−π, π].
pub fn wrap(a: f64) -> f64 {
    crate::sim::wrap_angle(a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::PI;

    fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
    }

    #[test]
    fn vectors_by_hand() {
        // 1 m north, 2 m east, 3 m down = 2 m east, 1 m north, 3 m below.
        assert_eq!(ned_to_enu([1.0, 2.0, 3.0]), [2.0, 1.0, -3.0]);
        assert_eq!(frd_to_flu([1.0, 2.0, 3.0]), [1.0, -2.0, -3.0]);
        assert_eq!(inertial_to_enu([1.0, 2.0, 3.0], Inertial::Enu), [1.0, 2.0, 3.0]);
    }

    #[test]
    fn quaternions_by_hand() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        // Identity in NED/FRD: nose north, level → ENU yaw +π/2, roll and pitch 0.
        let e = quat_to_euler_enu([1.0, 0.0, 0.0, 0.0], Inertial::Ned, Body::Frd).unwrap();
        assert!(close(&e, &[0.0, 0.0, FRAC_PI_2], 1e-15), "{e:?}");
        // 90° about NED down (heading east) → ENU yaw 0.
        let e = quat_to_euler_enu([s, 0.0, 0.0, s], Inertial::Ned, Body::Frd).unwrap();
        assert!(close(&e, &[0.0, 0.0, 0.0], 1e-15), "{e:?}");
        // 90° about ENU up → yaw π/2 in ENU/FLU.
        let e = quat_to_euler_enu([s, 0.0, 0.0, s], Inertial::Enu, Body::Flu).unwrap();
        assert!(close(&e, &[0.0, 0.0, FRAC_PI_2], 1e-15), "{e:?}");
        // 0.3 rad about body x (right wing down in FRD) → roll 0.3 in both conventions.
        let (h, c) = (0.15f64.sin(), 0.15f64.cos());
        let e = quat_to_euler_enu([c, h, 0.0, 0.0], Inertial::Ned, Body::Frd).unwrap();
        assert!(close(&e, &[0.3, 0.0, FRAC_PI_2], 1e-15), "{e:?}");
        // Nose up 0.2 rad in NED/FRD (positive pitch about body y, right) → ENU/FLU pitch −0.2
        // (about body y pointing left, nose up is negative).
        let (h, c) = (0.1f64.sin(), 0.1f64.cos());
        let e = quat_to_euler_enu([c, 0.0, h, 0.0], Inertial::Ned, Body::Frd).unwrap();
        assert!(close(&e, &[0.0, -0.2, FRAC_PI_2], 1e-15), "{e:?}");
        // A zero quaternion is no rotation.
        assert!(quat_to_euler_enu([0.0; 4], Inertial::Enu, Body::Flu).is_none());
    }

    #[test]
    fn euler_rates_by_hand() {
        // Level: body rates are Euler rates.
        let d = body_rates_to_euler_rates([0.1, 0.2, 0.3], [0.0, 0.0, 1.0]).unwrap();
        assert!(close(&d, &[0.1, 0.2, 0.3], 1e-15));
        // Rolled 90°: a body pitch rate q turns the heading (yaw rate q / cos 0), body yaw rate r
        // pitches down (pitch rate −r).
        let d = body_rates_to_euler_rates([0.0, 0.2, 0.3], [FRAC_PI_2, 0.0, 0.0]).unwrap();
        assert!(close(&d, &[0.0, -0.3, 0.2], 1e-15), "{d:?}");
        // Pitched 60°: yaw rate 1 about the vertical is p = −sin 60°, r = cos 60° in the body.
        let w = euler_rates_to_body_rates([0.0, 0.0, 1.0], [0.0, PI / 3.0, 0.0]);
        assert!(close(&w, &[-(PI / 3.0).sin(), 0.0, 0.5], 1e-15), "{w:?}");
        assert!(body_rates_to_euler_rates([0.0; 3], [0.0, FRAC_PI_2, 0.0]).is_none());
    }

    #[test]
    fn ned_heading() {
        assert_eq!(ned_yaw_to_enu(0.0), FRAC_PI_2);
        assert_eq!(ned_yaw_to_enu(FRAC_PI_2), 0.0);
        let e = euler_to_euler_enu([0.1, 0.2, 0.3], Inertial::Ned, Body::Frd);
        assert!(close(&e, &[0.1, -0.2, FRAC_PI_2 - 0.3], 1e-15), "{e:?}");
    }

    fn angles() -> impl Strategy<Value = [f64; 3]> {
        (-3.1f64..3.1, -1.5f64..1.5, -3.1f64..3.1).prop_map(|(a, b, c)| [a, b, c])
    }

    proptest! {
        #[test]
        fn euler_matrix_quaternion_round_trip(e in angles()) {
            let r = euler_to_matrix(e);
            prop_assert!(close(&matrix_to_euler(&r), &e, 1e-12));
            let q = matrix_to_quat(&r);
            let back = matrix_to_euler(&quat_to_matrix(q).unwrap());
            prop_assert!(close(&back, &e, 1e-12), "{:?} -> {:?} -> {:?}", e, q, back);
        }

        #[test]
        fn ned_frd_round_trip(e in angles()) {
            // An ENU/FLU attitude written as a NED/FRD quaternion (what PX4 logs) reads back.
            let ned = rotation_from_enu_flu(&euler_to_matrix(e), Inertial::Ned, Body::Frd);
            let q = matrix_to_quat(&ned);
            let back = quat_to_euler_enu(q, Inertial::Ned, Body::Frd).unwrap();
            prop_assert!(close(&back, &e, 1e-12), "{:?} {:?}", e, back);
            // And the closed form of the Euler mapping.
            let ned_euler = matrix_to_euler(&ned);
            prop_assert!((ned_euler[0] - e[0]).abs() < 1e-12);
            prop_assert!((ned_euler[1] + e[1]).abs() < 1e-12);
            prop_assert!((wrap(FRAC_PI_2 - ned_euler[2]) - wrap(e[2])).abs() < 1e-12);
        }

        #[test]
        fn rates_round_trip(e in angles(), d in angles()) {
            let w = euler_rates_to_body_rates(d, e);
            let back = body_rates_to_euler_rates(w, e).unwrap();
            prop_assert!(close(&back, &d, 1e-9), "{:?} {:?}", d, back);
            // Body rates are a body vector: FRD and back is the identity.
            prop_assert_eq!(frd_to_flu(frd_to_flu(w)), w);
        }

        #[test]
        fn rotation_acts_like_the_vector_maps(e in angles(), v in angles()) {
            // R_enu_flu · v_flu == ned_to_enu(R_ned_frd · frd(v)).
            let r = euler_to_matrix(e);
            let ned = rotation_from_enu_flu(&r, Inertial::Ned, Body::Frd);
            let apply = |m: &Mat3, x: [f64; 3]| [0, 1, 2].map(|i| (0..3).map(|k| m[i][k] * x[k]).sum::<f64>());
            let lhs = apply(&r, v);
            let rhs = ned_to_enu(apply(&ned, frd_to_flu(v)));
            prop_assert!(close(&lhs, &rhs, 1e-12));
        }
    }
}
