// Stub of PX4's generated uORB/topics/trajectory_setpoint.h: only the fields the skeleton uses (see ../../README.md).
#pragma once
#include <cstdint>
#include <drivers/drv_hrt.h>
struct trajectory_setpoint_s {
    uint64_t timestamp;
    float position[3];
    float velocity[3];
    float acceleration[3];
    float yaw;
    float yawspeed;
};
