// Stub of PX4's drivers/drv_hrt.h (see ../README.md).
#pragma once
#include <cstdint>
typedef uint64_t hrt_abstime;
inline hrt_abstime hrt_absolute_time() { return 0; }
