// Stub of PX4's generated uORB/topics/vehicle_attitude.h: only the fields the skeleton uses (see ../../README.md).
#pragma once
#include <cstdint>
#include <drivers/drv_hrt.h>
struct vehicle_attitude_s {
    uint64_t timestamp;
    float q[4];
};
