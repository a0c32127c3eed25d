// Flight-stack-agnostic C++17 wrapper of the C ABI of generated/sindy_m100 (uavgen --c-api,
// docs/c-api.md): the part of a PX4 module, ArduPilot library or ROS 2 node that does not depend on
// the flight stack. No heap, no exceptions, no RTTI: the solver's storage is a member, so the
// object lives wherever its owner puts it (a static, a member of the module, the stack of a
// thread that has ~300 KB of it).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "sindy_m100.h"

namespace uavgen {

class SindyM100Mpc {
public:
    static constexpr std::size_t NX = SINDY_M100_NX;
    static constexpr std::size_t NU = SINDY_M100_NU;
    static constexpr std::size_t N = SINDY_M100_N;
    static constexpr double DT = SINDY_M100_DT;

    using Real = sindy_m100_real;
    using State = std::array<Real, NX>;
    using Input = std::array<Real, NU>;
    /// The reference over the horizon: stages 0..N, NX states each (row-major, as the ABI wants).
    using Window = std::array<State, N + 1>;

    enum class Status : std::int32_t {
        Solved = SINDY_M100_SOLVED,
        IterationCap = SINDY_M100_ITERATION_CAP,
        HessianRegularised = SINDY_M100_HESSIAN_REGULARISED,
        InvalidInput = SINDY_M100_INVALID_INPUT,
        NumericalFailure = SINDY_M100_NUMERICAL_FAILURE,
        OutOfEnvelope = SINDY_M100_OUT_OF_ENVELOPE,
        NullPointer = SINDY_M100_NULL_POINTER,
        Misaligned = SINDY_M100_MISALIGNED,
        StorageTooSmall = SINDY_M100_STORAGE_TOO_SMALL,
        NotInitialised = SINDY_M100_NOT_INITIALISED,
        Overlap = SINDY_M100_OVERLAP,
        NoSolution = SINDY_M100_NO_SOLUTION,
    };

    /// True for the solver's statuses: an input was produced, finite and within the bounds.
    static constexpr bool has_input(Status s) { return static_cast<std::int32_t>(s) >= 0; }

    static_assert(sizeof(Window) == sizeof(Real) * (N + 1) * NX, "Window must be contiguous");

    /// Guess: the state x0 everywhere, the input u everywhere.
    Status init(const State &x0, const Input &u) {
        return wrap(sindy_m100_init(&storage_, sizeof(storage_), x0.data(), u.data()));
    }
    /// Linearise and factorise for the next window (before the measurement arrives).
    Status prepare(const Window &reference) { return wrap(sindy_m100_prepare(&storage_, reference[0].data())); }
    /// The measured state in, the input to apply out.
    Status feedback(const State &x, Input &u) { return wrap(sindy_m100_feedback(&storage_, x.data(), u.data())); }
    /// One sample ahead (after applying u, before the next prepare).
    Status shift() { return wrap(sindy_m100_shift(&storage_)); }
    std::uint32_t qp_iterations() const {
        std::uint32_t n = 0;
        return sindy_m100_qp_iterations(&storage_, &n) == SINDY_M100_OK ? n : 0;
    }
    /// The model over one sample (a stand-in plant, or a predictor over known delays).
    static State predict(const State &x, const Input &u) {
        State next{};
        sindy_m100_discrete_dynamics(x.data(), u.data(), next.data());
        return next;
    }

private:
    static Status wrap(sindy_m100_status s) { return static_cast<Status>(s); }
    sindy_m100_storage storage_{};
};

}  // namespace uavgen
