// Stub of PX4's px4_work_queue/ScheduledWorkItem.hpp (see ../../README.md).
#pragma once
#include <cstdint>

namespace px4 {
// As PX4's (px4_work_queue/WorkQueueManager.hpp): a work queue is a thread created on first use
// from its configuration, with this stack.
struct wq_config_t {
    const char *name;
    uint16_t stacksize;
    int8_t relative_priority;
};
namespace wq_configurations {
static constexpr wq_config_t nav_and_controllers{"wq:nav_and_controllers", 2240, -13};
}
class ScheduledWorkItem {
public:
    ScheduledWorkItem(const char *name, const wq_config_t &config) : _name(name), _config(config) {}
    const wq_config_t &work_queue() const { return _config; }
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
