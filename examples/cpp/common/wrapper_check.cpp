// Host check of the flight-stack-agnostic part (uavgen_mpc.hpp, frames.hpp), built and run by
// `make -C examples/cpp` in CI: the C++ wrapper flies a hover-to-setpoint loop with the model as
// the plant, and the frame conversions pass their identities. Exit status 1 on a failure.
#include <cmath>
#include <cstdio>

#include "frames.hpp"
#include "uavgen_mpc.hpp"

namespace {
int failures = 0;
void check(bool ok, const char *what) {
    if (!ok) {
        std::fprintf(stderr, "check failed: %s\n", what);
        failures++;
    }
}
bool near(double a, double b) { return std::fabs(a - b) < 1e-12; }

// One solver as a static: 300 KB do not belong on a thread's stack.
uavgen::SindyM100Mpc mpc;
}  // namespace

int main() {
    using Mpc = uavgen::SindyM100Mpc;
    Mpc::State x{};
    Mpc::Window window{};
    for (auto &stage : window) {
        stage[0] = 1.0;  // 1 m east
        stage[2] = 0.5;  // 0.5 m up
    }
    check(mpc.init(x, {}) == Mpc::Status::Solved, "init");
    check(Mpc::has_input(mpc.prepare(window)), "prepare");
    Mpc::Input u{};
    for (int k = 0; k < 300; k++) {
        const Mpc::Status s = mpc.feedback(x, u);
        check(s == Mpc::Status::Solved || s == Mpc::Status::IterationCap, "feedback status");
        x = Mpc::predict(x, u);
        check(mpc.shift() == Mpc::Status::Solved, "shift");
        check(Mpc::has_input(mpc.prepare(window)), "prepare");
    }
    const double error = std::hypot(x[0] - 1.0, x[1], x[2] - 0.5);
    check(error < 0.05, "position after 10 s within 5 cm of the setpoint");

    // Frames: level, facing north in NED (identity quaternion) is yaw = pi/2 in ENU.
    uavgen::NedEstimate e{{1.0, 2.0, -3.0}, {0.5, -0.5, 0.25}, {1.0, 0.0, 0.0, 0.0}, {0.1, 0.2, 0.3}};
    const uavgen::State12 s = uavgen::state_from_ned(e);
    check(near(s[0], 2.0) && near(s[1], 1.0) && near(s[2], 3.0), "position NED -> ENU");
    check(near(s[6], -0.5) && near(s[7], 0.5) && near(s[8], -0.25), "velocity NED -> ENU");
    check(near(s[3], 0.0) && near(s[4], 0.0) && near(s[5], 1.5707963267948966), "attitude: yaw 0 NED = pi/2 ENU");
    check(near(s[9], 0.1) && near(s[10], -0.2) && near(s[11], -0.3), "level: Euler rates = FLU body rates");
    // Yaw 90 deg NED (facing east) is yaw 0 in ENU.
    const double h = std::sqrt(0.5);
    uavgen::NedEstimate east{{0, 0, 0}, {0, 0, 0}, {h, 0.0, 0.0, h}, {0, 0, 0}};
    check(std::fabs(uavgen::state_from_ned(east)[5]) < 1e-12, "facing east: ENU yaw 0");
    const double cmd[4] = {1.0, 0.1, 0.2, 0.3};
    const uavgen::NedCommand c = uavgen::command_to_ned(cmd);
    check(c.vz_down == -1.0 && c.roll == 0.1 && c.pitch == -0.2 && c.yaw_rate == -0.3, "command ENU -> NED");

    if (failures) {
        return 1;
    }
    std::printf("wrapper-check ok: %zu-byte solver, position error %.4f m after 300 steps, %u QP iterations last\n",
                sizeof(Mpc), error, mpc.qp_iterations());
    return 0;
}
