// Stub of PX4's uORB/Subscription.hpp (see ../README.md).
#pragma once
namespace uORB {
struct orb_id_t {
    const char *name;
};
class Subscription {
public:
    explicit Subscription(orb_id_t id) : _id(id) {}
    template <class T>
    bool update(T *data) {
        (void)data;
        return false;
    }

private:
    orb_id_t _id;
};
}  // namespace uORB
#define ORB_ID(name) (uORB::orb_id_t{#name})
