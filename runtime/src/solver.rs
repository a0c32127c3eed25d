//! The solver interface ([`MpcSolver`]) and the adapter macro for generated crates
//! ([`mpc_adapter!`](crate::mpc_adapter)).

use crate::Real;

/// Outcome of a solver call; the same variants as a generated crate's `Status` (docs/mpc.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Status {
    /// The QP was solved to optimality.
    Solved,
    /// The QP hit its iteration cap; the best bounded iterate is applied.
    IterationCap,
    /// The Hessian was not numerically positive definite; a multiple of I was added.
    HessianRegularised,
    /// Non-finite x₀ or reference: the previous plan is kept and `u0` is its first input.
    InvalidInput,
    /// A non-finite value appeared; the previous plan is kept.
    NumericalFailure,
    /// x₀ or the reference lies outside the generated crate's `ENVELOPE_LO`..`ENVELOPE_HI`: the input is finite and
    /// within bounds but extrapolates the model far beyond its data.
    OutOfEnvelope,
}

impl Status {
    /// `true` for `Solved`, `IterationCap` and `HessianRegularised`: the input comes from a QP
    /// solved for the current measurement.
    pub fn is_usable(self) -> bool {
        matches!(self, Status::Solved | Status::IterationCap | Status::HessianRegularised)
    }
}

impl core::fmt::Display for Status {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Status::Solved => "solved",
            Status::IterationCap => "QP iteration cap reached",
            Status::HessianRegularised => "Hessian regularised",
            Status::InvalidInput => "invalid input (previous plan kept)",
            Status::NumericalFailure => "numerical failure (previous plan kept)",
            Status::OutOfEnvelope => "state or reference outside the model's envelope",
        })
    }
}

/// Result of [`MpcSolver::feedback`]; the same fields as a generated crate's `Solution`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Solution<R, const NU: usize> {
    /// The input to apply now.
    pub u0: [R; NU],
    /// How the solve went.
    pub status: Status,
    /// Active-set iterations of the QP.
    pub qp_iterations: usize,
    /// Cost of the updated guess.
    pub cost: R,
}

/// A real-time-iteration MPC solver with `NX` states, `NU` inputs and `N1 = N + 1` shooting nodes
/// (horizon `N`; stable Rust cannot write `N + 1` in a generic, so it is its own parameter).
///
/// The timeline ([`Controller`](crate::Controller) drives it): `prepare(reference)` before the
/// measurement is available, `feedback(x0)` as soon as it is, `shift()` when time advances by `DT`.
/// A generated crate's `Mpc` implements it through [`mpc_adapter!`](crate::mpc_adapter); so does
/// `&mut S` for every solver `S`, so a controller can borrow a solver that lives elsewhere (a
/// generated `Mpc` is hundreds of KB; moving it costs stack).
pub trait MpcSolver<R: Real, const NX: usize, const NU: usize, const N1: usize> {
    /// Sample period in s.
    const DT: R;
    /// Lower input bounds.
    const U_MIN: [R; NU];
    /// Upper input bounds.
    const U_MAX: [R; NU];

    /// Reset the guess to the constant state `x0` and input `u` (a prepared QP is invalidated).
    fn initialize(&mut self, x0: &[R; NX], u: &[R; NU]);
    /// Linearise and condense along the guess for the reference window `reference[k]` = r(t + k·DT),
    /// k = 0..N; everything that does not need the measurement.
    fn prepare(&mut self, reference: &[[R; NX]; N1]) -> Status;
    /// Solve the prepared QP for the measured state `x0` and update the guess.
    fn feedback(&mut self, x0: &[R; NX]) -> Solution<R, NU>;
    /// Shift the guess by one sample.
    fn shift(&mut self);
    /// Predict with the disturbance e (x⁺ = F(x, u) + e) from the next `prepare` on; false if the
    /// solver does not take one (the default) or refused it (a non-finite value).
    fn set_disturbance(&mut self, _e: &[R; NX]) -> bool {
        false
    }
}

impl<R, S, const NX: usize, const NU: usize, const N1: usize> MpcSolver<R, NX, NU, N1> for &mut S
where
    R: Real,
    S: MpcSolver<R, NX, NU, N1> + ?Sized,
{
    const DT: R = S::DT;
    const U_MIN: [R; NU] = S::U_MIN;
    const U_MAX: [R; NU] = S::U_MAX;

    fn initialize(&mut self, x0: &[R; NX], u: &[R; NU]) {
        S::initialize(self, x0, u)
    }
    fn prepare(&mut self, reference: &[[R; NX]; N1]) -> Status {
        S::prepare(self, reference)
    }
    fn feedback(&mut self, x0: &[R; NX]) -> Solution<R, NU> {
        S::feedback(self, x0)
    }
    fn shift(&mut self) {
        S::shift(self)
    }
    fn set_disturbance(&mut self, e: &[R; NX]) -> bool {
        S::set_disturbance(self, e)
    }
}

/// Defines a newtype around a generated crate's `Mpc` that implements
/// [`MpcSolver`](crate::MpcSolver)`<K::Real, {K::NX}, {K::NU}, {K::N + 1}>` (K = the crate).
///
/// ```ignore
/// uavgen_runtime::mpc_adapter!(
///     /// The SINDy M100 MPC.
///     pub struct SindyMpc(sindy_m100);
/// );
/// ```
///
/// Syntax: optional attributes (doc comments, `#[derive]`s the `Mpc` supports), an optional
/// visibility, `struct`, the new type's name, and in parentheses the generated crate's name (an
/// identifier: the crate, or a module or `use … as` alias that re-exports its items). The crate must
/// provide the generated MPC API of docs/mpc.md (`Real`, `NX`, `NU`, `N`, `DT`, `U_MIN`, `U_MAX`,
/// `Status`, `Solution`, `Mpc`).
///
/// The new type has the inherent methods `const fn new()` (= `Mpc::new()`, which generated crates
/// declare `const`, so the solver can be a `static`), `inner()`, `inner_mut()`, `into_inner()`,
/// `planned_inputs()` and `predicted_states()`, implements `Default`, and implements the trait by
/// forwarding to the `Mpc` and converting its `Status` and `Solution` into the runtime's.
#[macro_export]
macro_rules! mpc_adapter {
    ($(#[$attr:meta])* $vis:vis struct $name:ident($krate:ident) $(;)?) => {
        $(#[$attr])*
        $vis struct $name($krate::Mpc);

        #[allow(dead_code)]
        impl $name {
            /// A solver with the generated crate's initial guess (`Mpc::new()`). `const`, so the
            /// solver can be a `static` initialised at compile time (no copy through the stack).
            #[inline]
            pub const fn new() -> Self {
                Self($krate::Mpc::new())
            }
            /// The generated `Mpc`.
            #[inline]
            pub fn inner(&self) -> &$krate::Mpc {
                &self.0
            }
            /// The generated `Mpc`, mutably.
            #[inline]
            pub fn inner_mut(&mut self) -> &mut $krate::Mpc {
                &mut self.0
            }
            /// The generated `Mpc`.
            #[inline]
            pub fn into_inner(self) -> $krate::Mpc {
                self.0
            }
            /// The planned inputs ū₀..ū_{N−1} of the current guess.
            #[inline]
            pub fn planned_inputs(&self) -> &[[$krate::Real; $krate::NU]; $krate::N] {
                self.0.planned_inputs()
            }
            /// The predicted states x̄₀..x̄_N of the current guess.
            #[inline]
            pub fn predicted_states(&self) -> &[[$krate::Real; $krate::NX]; $krate::N + 1] {
                self.0.predicted_states()
            }
            #[inline]
            fn convert_status(status: &$krate::Status) -> $crate::Status {
                match status {
                    $krate::Status::Solved => $crate::Status::Solved,
                    $krate::Status::IterationCap => $crate::Status::IterationCap,
                    $krate::Status::HessianRegularised => $crate::Status::HessianRegularised,
                    $krate::Status::InvalidInput => $crate::Status::InvalidInput,
                    $krate::Status::NumericalFailure => $crate::Status::NumericalFailure,
                    $krate::Status::OutOfEnvelope => $crate::Status::OutOfEnvelope,
                }
            }
        }

        impl ::core::default::Default for $name {
            #[inline]
            fn default() -> Self {
                Self::new()
            }
        }

        impl $crate::MpcSolver<$krate::Real, { $krate::NX }, { $krate::NU }, { $krate::N + 1 }> for $name {
            const DT: $krate::Real = $krate::DT;
            const U_MIN: [$krate::Real; $krate::NU] = $krate::U_MIN;
            const U_MAX: [$krate::Real; $krate::NU] = $krate::U_MAX;

            #[inline]
            fn initialize(&mut self, x0: &[$krate::Real; $krate::NX], u: &[$krate::Real; $krate::NU]) {
                self.0.initialize(x0, u)
            }
            #[inline]
            fn prepare(&mut self, reference: &[[$krate::Real; $krate::NX]; $krate::N + 1]) -> $crate::Status {
                let status = self.0.prepare(reference);
                Self::convert_status(&status)
            }
            #[inline]
            fn feedback(&mut self, x0: &[$krate::Real; $krate::NX]) -> $crate::Solution<$krate::Real, { $krate::NU }> {
                let solution = self.0.feedback(x0);
                $crate::Solution {
                    u0: solution.u0,
                    status: Self::convert_status(&solution.status),
                    qp_iterations: solution.qp_iterations,
                    cost: solution.cost,
                }
            }
            #[inline]
            fn shift(&mut self) {
                self.0.shift()
            }
            #[inline]
            fn set_disturbance(&mut self, e: &[$krate::Real; $krate::NX]) -> bool {
                self.0.set_disturbance(e)
            }
        }
    };
}
