// Stub of PX4's generated uORB/topics/vehicle_angular_velocity.h: only the fields the skeleton uses (see ../../README.md).
#pragma once
#include <cstdint>
#include <drivers/drv_hrt.h>
struct vehicle_angular_velocity_s {
    uint64_t timestamp;
    float xyz[3];
};
