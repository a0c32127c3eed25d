// Stub of PX4's px4_platform_common/defines.h (see ../README.md).
#pragma once
#include <cstdio>
#define PX4_OK 0
#define PX4_ERROR (-1)
#define PX4_INFO(...) (std::printf(__VA_ARGS__), std::printf("\n"))
#define PX4_WARN(...) (std::fprintf(stderr, __VA_ARGS__), std::fprintf(stderr, "\n"))
#define PX4_ERR(...) (std::fprintf(stderr, __VA_ARGS__), std::fprintf(stderr, "\n"))
#define __EXPORT __attribute__((visibility("default")))
