// Stub of PX4's uORB/Publication.hpp (see ../README.md).
#pragma once
#include <uORB/Subscription.hpp>
namespace uORB {
template <class T>
class Publication {
public:
    explicit Publication(orb_id_t id) : _id(id) {}
    bool publish(const T &data) {
        (void)data;
        return true;
    }

private:
    orb_id_t _id;
};
}  // namespace uORB
