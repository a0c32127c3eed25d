// Stub of PX4's generated uORB/topics/vehicle_attitude_setpoint.h: only the fields the skeleton uses (see ../../README.md).
#pragma once
#include <cstdint>
#include <drivers/drv_hrt.h>
struct vehicle_attitude_setpoint_s {
    uint64_t timestamp;
    float q_d[4];
    float thrust_body[3];
    float yaw_sp_move_rate;
};
