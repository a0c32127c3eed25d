// Stub of PX4's px4_work_queue/ScheduledWorkItem.hpp (see ../../README.md).
#pragma once
#include <cstdint>

namespace px4 {
struct wq_config_t {
    const char *name;
};
namespace wq_configurations {
static constexpr wq_config_t nav_and_controllers{"wq:nav_and_controllers"};
}
class ScheduledWorkItem {
public:
    ScheduledWorkItem(const char *name, const wq_config_t &config) : _name(name), _config(config) {}
    virtual ~ScheduledWorkItem() = default;
    void ScheduleOnInterval(uint32_t interval_us) { _interval_us = interval_us; }
    void ScheduleClear() { _interval_us = 0; }

protected:
    virtual void Run() = 0;

private:
    const char *_name;
    wq_config_t _config;
    uint32_t _interval_us{0};
};
}  // namespace px4
