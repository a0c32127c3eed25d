// Stub of PX4's generated uORB/topics/vehicle_local_position.h: only the fields the skeleton uses (see ../../README.md).
#pragma once
#include <cstdint>
#include <drivers/drv_hrt.h>
struct vehicle_local_position_s {
    uint64_t timestamp;
    bool xy_valid;
    bool z_valid;
    bool v_xy_valid;
    bool v_z_valid;
    float x;
    float y;
    float z;
    float vx;
    float vy;
    float vz;
};
