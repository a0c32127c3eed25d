// Stub of PX4's px4_platform_common/module.h (see ../README.md).
#pragma once
#include <atomic>
#include <cstring>

#define PRINT_MODULE_DESCRIPTION(text) ((void)(text))
#define PRINT_MODULE_USAGE_NAME(name, category) ((void)(name), (void)(category))
#define PRINT_MODULE_USAGE_COMMAND(name) ((void)(name))

static constexpr int task_id_is_work_queue = -2;

template <class T>
class ModuleBase {
public:
    virtual ~ModuleBase() = default;
    static int main(int argc, char *argv[]) {
        if (argc >= 2 && std::strcmp(argv[1], "start") == 0) {
            return T::task_spawn(argc - 1, argv + 1);
        }
        return T::custom_command(argc - 1, argv + 1);
    }
    virtual int print_status() { return 0; }
    bool should_exit() const { return _should_exit.load(); }
    void request_stop() { _should_exit.store(true); }
    static void exit_and_cleanup() {
        delete _object.load();
        _object.store(nullptr);
        _task_id = -1;
    }

protected:
    static inline std::atomic<T *> _object{nullptr};
    static inline int _task_id{-1};

private:
    std::atomic<bool> _should_exit{false};
};
