// PX4 module skeleton: see uavgen_mpc_module.hpp. The RTI timeline per 1/30 s work-queue cycle:
//   read the estimate -> feedback -> publish the setpoint -> shift -> prepare the next window.
#include "uavgen_mpc_module.hpp"

#include <cmath>
#include <cstring>
#include <initializer_list>

namespace {
constexpr double kHoverThrust = 0.5;  // TODO vehicle: normalised hover thrust (PX4's MPC_THR_HOVER)
constexpr double kVzGain = 0.15;      // TODO vehicle: thrust per m/s of vertical-velocity error
}  // namespace

namespace {
constexpr uint16_t max_stack(std::initializer_list<unsigned> v) {
    unsigned m = 0;
    for (unsigned x : v) m = x > m ? x : m;
    return static_cast<uint16_t>(m);
}
// The module's own work queue (PX4 creates it on first use). PX4's wq:nav_and_controllers has a
// 2,240 B stack, far below what the solver needs: the header's measured thumbv7em bounds
// (SINDY_M100_STACK_*, checked in uavgen's CI), the largest of the calls Run() makes, plus 2 KiB for
// Run()'s own frame (the reference window, (N+1)·NX doubles = 2,976 B, lives in the object, not
// on the stack), the C++ wrapper and PX4's work-queue frames. Interrupts run on NuttX's interrupt
// stack. Priority: nav_and_controllers' (-13).
constexpr uint16_t kSolverStack = max_stack({SINDY_M100_STACK_INIT, SINDY_M100_STACK_PREPARE,
                                             SINDY_M100_STACK_FEEDBACK, SINDY_M100_STACK_SHIFT,
                                             SINDY_M100_STACK_DISCRETE_DYNAMICS});
constexpr px4::wq_config_t kUavgenMpcWorkQueue{"wq:uavgen_mpc", static_cast<uint16_t>(kSolverStack + 2048), -13};
static_assert(kUavgenMpcWorkQueue.stacksize > px4::wq_configurations::nav_and_controllers.stacksize,
              "the solver does not fit PX4's nav_and_controllers stack");
}  // namespace

UavgenMpc::UavgenMpc() : ScheduledWorkItem(MODULE_NAME, kUavgenMpcWorkQueue) {}

bool UavgenMpc::init() {
    // The model's rate: DT = 1/30 s.
    ScheduleOnInterval(static_cast<uint32_t>(uavgen::SindyM100Mpc::DT * 1e6));
    return true;
}

bool UavgenMpc::read_state(uavgen::SindyM100Mpc::State &x) {
    _local_position_sub.update(&_local_position);
    _attitude_sub.update(&_attitude);
    _angular_velocity_sub.update(&_angular_velocity);
    if (_local_position.timestamp == 0 || _attitude.timestamp == 0 || _angular_velocity.timestamp == 0 ||
        !_local_position.xy_valid || !_local_position.z_valid || !_local_position.v_xy_valid ||
        !_local_position.v_z_valid) {
        return false;
    }
    uavgen::NedEstimate e{};
    e.position_ned[0] = _local_position.x;
    e.position_ned[1] = _local_position.y;
    e.position_ned[2] = _local_position.z;
    e.velocity_ned[0] = _local_position.vx;
    e.velocity_ned[1] = _local_position.vy;
    e.velocity_ned[2] = _local_position.vz;
    for (int i = 0; i < 4; i++) e.q_frd_to_ned[i] = _attitude.q[i];
    for (int i = 0; i < 3; i++) e.body_rates_frd[i] = _angular_velocity.xyz[i];
    x = uavgen::state_from_ned(e);
    return true;
}

void UavgenMpc::update_window() {
    _trajectory_setpoint_sub.update(&_trajectory_setpoint);
    uavgen::SindyM100Mpc::State r{};
    // NED position setpoint -> ENU; NaN (unset) components keep the previous reference.
    const float *p = _trajectory_setpoint.position;
    const double enu[3] = {p[1], p[0], -p[2]};
    for (int i = 0; i < 3; i++) r[i] = std::isfinite(enu[i]) ? enu[i] : _window[0][i];
    r[5] = std::isfinite(_trajectory_setpoint.yaw) ? uavgen::wrap_pi(1.5707963267948966 - _trajectory_setpoint.yaw)
                                                   : _window[0][5];
    // Held over the horizon; a planner would fill stages 1..N with its predicted setpoints.
    for (auto &stage : _window) stage = r;
}

void UavgenMpc::publish(const uavgen::SindyM100Mpc::Input &u, const uavgen::SindyM100Mpc::State &x) {
    const uavgen::NedCommand c = uavgen::command_to_ned(u.data());
    _yaw_setpoint = uavgen::wrap_pi(_yaw_setpoint + c.yaw_rate * uavgen::SindyM100Mpc::DT);
    // ZYX Euler (NED/FRD) -> quaternion.
    const double cr = std::cos(c.roll / 2), sr = std::sin(c.roll / 2), cp = std::cos(c.pitch / 2),
                 sp = std::sin(c.pitch / 2), cy = std::cos(_yaw_setpoint / 2), sy = std::sin(_yaw_setpoint / 2);
    vehicle_attitude_setpoint_s sp_msg{};
    sp_msg.timestamp = hrt_absolute_time();
    sp_msg.q_d[0] = static_cast<float>(cr * cp * cy + sr * sp * sy);
    sp_msg.q_d[1] = static_cast<float>(sr * cp * cy - cr * sp * sy);
    sp_msg.q_d[2] = static_cast<float>(cr * sp * cy + sr * cp * sy);
    sp_msg.q_d[3] = static_cast<float>(cr * cp * sy - sr * sp * cy);
    sp_msg.yaw_sp_move_rate = static_cast<float>(c.yaw_rate);
    // u_vz is a vertical-velocity reference (the M100's autopilot mode); PX4's attitude setpoint
    // wants thrust, so a vehicle-specific vertical-velocity loop closes it here (TODO vehicle).
    const double vz_down = -x[8];
    const double thrust = kHoverThrust - kVzGain * (c.vz_down - vz_down);
    sp_msg.thrust_body[2] = static_cast<float>(-(thrust < 0.1 ? 0.1 : (thrust > 0.9 ? 0.9 : thrust)));
    _attitude_setpoint_pub.publish(sp_msg);
}

void UavgenMpc::Run() {
    if (should_exit()) {
        ScheduleClear();
        exit_and_cleanup();
        return;
    }
    uavgen::SindyM100Mpc::State x{};
    if (!read_state(x)) {
        return;
    }
    using Status = uavgen::SindyM100Mpc::Status;
    if (!_started) {
        _yaw_setpoint = uavgen::wrap_pi(1.5707963267948966 - x[5]);  // NED yaw of the current attitude
        for (auto &stage : _window) stage = x;  // hold the current pose until a setpoint arrives
        if (_mpc.init(x, {}) != Status::Solved || !uavgen::SindyM100Mpc::has_input(_mpc.prepare(_window))) {
            return;
        }
        _started = true;
    }
    uavgen::SindyM100Mpc::Input u{};
    const Status status = _mpc.feedback(x, u);
    if (!uavgen::SindyM100Mpc::has_input(status)) {
        _rejected++;  // a rejected call: nothing to apply (not reachable with the pointers above)
        return;
    }
    publish(u, x);  // finite and within [U_MIN, U_MAX] whatever the status
    _steps++;
    const uint32_t it = _mpc.qp_iterations();
    _max_qp_iterations = it > _max_qp_iterations ? it : _max_qp_iterations;
    // The rest of the cycle: everything that does not need the next measurement.
    _mpc.shift();
    update_window();
    _mpc.prepare(_window);
}

int UavgenMpc::task_spawn(int argc, char *argv[]) {
    (void)argc;
    (void)argv;
    UavgenMpc *instance = new UavgenMpc();  // once, at start-up
    if (instance) {
        _object.store(instance);
        _task_id = task_id_is_work_queue;
        if (instance->init()) {
            return PX4_OK;
        }
    } else {
        PX4_ERR("alloc failed");
    }
    delete instance;
    _object.store(nullptr);
    _task_id = -1;
    return PX4_ERROR;
}

int UavgenMpc::print_status() {
    PX4_INFO("%s: %u steps, %u rejected, max %u QP iterations, storage %zu bytes", SINDY_M100_MODEL_NAME,
             (unsigned)_steps, (unsigned)_rejected, (unsigned)_max_qp_iterations, sindy_m100_storage_size());
    return 0;
}

int UavgenMpc::custom_command(int argc, char *argv[]) {
    (void)argc;
    (void)argv;
    return print_usage("unknown command");
}

int UavgenMpc::print_usage(const char *reason) {
    if (reason) {
        PX4_WARN("%s", reason);
    }
    PRINT_MODULE_DESCRIPTION("uavgen-generated MPC (sindy_m100) through its C ABI");
    PRINT_MODULE_USAGE_NAME("uavgen_mpc", "controller");
    PRINT_MODULE_USAGE_COMMAND("start");
    return 0;
}

extern "C" __EXPORT int uavgen_mpc_main(int argc, char *argv[]) { return UavgenMpc::main(argc, argv); }
