// Frame conversions between a flight stack's estimate (PX4, ArduPilot, MAVROS: NED world, FRD body,
// quaternions, body rates) and the state of a uavgen model (ENU world, FLU body, ZYX Euler angles,
// Euler-angle rates; docs/log-format.md), and back for the inputs. Header-only, no allocation.
#pragma once

#include <array>
#include <cmath>

namespace uavgen {

/// The model's state order: x y z roll pitch yaw vx vy vz roll_rate pitch_rate yaw_rate.
using State12 = std::array<double, 12>;

/// One estimate in the flight stack's frames.
struct NedEstimate {
    double position_ned[3];       // m
    double velocity_ned[3];       // m/s
    double q_frd_to_ned[4];       // w, x, y, z: rotates FRD body vectors into NED
    double body_rates_frd[3];     // rad/s about the FRD axes
};

inline double wrap_pi(double a) {
    const double two_pi = 6.283185307179586;
    a = std::fmod(a + 3.141592653589793, two_pi);
    if (a < 0.0) a += two_pi;
    return a - 3.141592653589793;
}

/// NED/FRD estimate -> the model's ENU/FLU state.
inline State12 state_from_ned(const NedEstimate &e) {
    const double w = e.q_frd_to_ned[0], x = e.q_frd_to_ned[1], y = e.q_frd_to_ned[2], z = e.q_frd_to_ned[3];
    // ZYX Euler angles of the FRD->NED rotation.
    const double roll_ned = std::atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y));
    const double s = 2.0 * (w * y - z * x);
    const double pitch_ned = std::asin(s > 1.0 ? 1.0 : (s < -1.0 ? -1.0 : s));
    const double yaw_ned = std::atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z));
    // FLU->ENU = T_world * (FRD->NED) * T_body: roll stays, pitch flips, yaw = pi/2 - yaw_ned.
    const double roll = roll_ned, pitch = -pitch_ned, yaw = wrap_pi(1.5707963267948966 - yaw_ned);
    // Body rates FRD -> FLU, then to Euler-angle rates (ZYX).
    const double p = e.body_rates_frd[0], q = -e.body_rates_frd[1], r = -e.body_rates_frd[2];
    const double sr = std::sin(roll), cr = std::cos(roll), cp = std::cos(pitch), tp = std::tan(pitch);
    State12 out{};
    out[0] = e.position_ned[1];
    out[1] = e.position_ned[0];
    out[2] = -e.position_ned[2];
    out[3] = roll;
    out[4] = pitch;
    out[5] = yaw;
    out[6] = e.velocity_ned[1];
    out[7] = e.velocity_ned[0];
    out[8] = -e.velocity_ned[2];
    out[9] = p + sr * tp * q + cr * tp * r;
    out[10] = cr * q - sr * r;
    out[11] = (sr * q + cr * r) / cp;
    return out;
}

/// The model's inputs [u_vz (up), u_roll, u_pitch (FLU/ENU), u_yaw_rate (ENU)] in NED/FRD terms.
struct NedCommand {
    double vz_down;      // m/s, NED (positive down)
    double roll;         // rad, FRD
    double pitch;        // rad, FRD (nose up positive)
    double yaw_rate;     // rad/s, NED yaw (clockwise seen from above)
};

inline NedCommand command_to_ned(const double u[4]) {
    return NedCommand{-u[0], u[1], -u[2], -u[3]};
}

}  // namespace uavgen
