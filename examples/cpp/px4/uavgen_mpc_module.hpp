// PX4 module skeleton around the C ABI of generated/sindy_m100 (docs/c-api.md, "PX4").
//
// Compiled in CI (tests/c_abi.rs, `make -C examples/cpp`) against stubs/ — minimal stand-ins for the
// PX4 headers it includes — because PX4 itself (its source tree, NuttX and the arm-none-eabi
// toolchain) is not installable here. In a PX4 tree, drop stubs/, copy this directory to
// src/modules/uavgen_mpc/ with the CMakeLists.txt and Kconfig of docs/c-api.md, and link
// libsindy_m100_capi.a built for thumbv7em-none-eabihf.
#pragma once

#include <px4_platform_common/defines.h>
#include <px4_platform_common/module.h>
#include <px4_platform_common/px4_work_queue/ScheduledWorkItem.hpp>
#include <uORB/Publication.hpp>
#include <uORB/Subscription.hpp>
#include <uORB/topics/trajectory_setpoint.h>
#include <uORB/topics/vehicle_angular_velocity.h>
#include <uORB/topics/vehicle_attitude.h>
#include <uORB/topics/vehicle_attitude_setpoint.h>
#include <uORB/topics/vehicle_local_position.h>

#include "../common/frames.hpp"
#include "../common/uavgen_mpc.hpp"

class UavgenMpc : public ModuleBase<UavgenMpc>, public px4::ScheduledWorkItem {
public:
    UavgenMpc();
    ~UavgenMpc() override = default;

    static int task_spawn(int argc, char *argv[]);
    static int custom_command(int argc, char *argv[]);
    static int print_usage(const char *reason = nullptr);

    bool init();
    int print_status() override;

private:
    void Run() override;
    /// The latest estimate in the model's frames; false if a topic has not been published yet.
    bool read_state(uavgen::SindyM100Mpc::State &x);
    /// The reference window from the latest trajectory setpoint (held over the horizon).
    void update_window();
    void publish(const uavgen::SindyM100Mpc::Input &u, const uavgen::SindyM100Mpc::State &x);

    uORB::Subscription _local_position_sub{ORB_ID(vehicle_local_position)};
    uORB::Subscription _attitude_sub{ORB_ID(vehicle_attitude)};
    uORB::Subscription _angular_velocity_sub{ORB_ID(vehicle_angular_velocity)};
    uORB::Subscription _trajectory_setpoint_sub{ORB_ID(trajectory_setpoint)};
    uORB::Publication<vehicle_attitude_setpoint_s> _attitude_setpoint_pub{ORB_ID(vehicle_attitude_setpoint)};

    vehicle_local_position_s _local_position{};
    vehicle_attitude_s _attitude{};
    vehicle_angular_velocity_s _angular_velocity{};
    trajectory_setpoint_s _trajectory_setpoint{};

    // ~300 KB: the module object is allocated once at start-up (task_spawn); the solver never allocates.
    uavgen::SindyM100Mpc _mpc{};
    uavgen::SindyM100Mpc::Window _window{};
    bool _started{false};
    double _yaw_setpoint{0.0};
    uint32_t _steps{0};
    uint32_t _rejected{0};
    uint32_t _max_qp_iterations{0};
};
