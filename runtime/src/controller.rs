//! The real-time-iteration timeline around an [`MpcSolver`], with validation and timings.

use crate::delay::{NoDelay, StatePredictor};
use crate::reference::{ReferenceError, ReferenceSource};
use crate::solver::{MpcSolver, Solution, Status};
use crate::Real;

/// A free-running cycle counter the firmware provides (on a Cortex-M, DWT `CYCCNT`). The value
/// wraps; differences are taken with `wrapping_sub`, so one measured phase must take fewer than
/// 2³² cycles.
pub trait CycleCounter {
    /// The current count.
    fn cycles(&mut self) -> u32;
}

/// A counter that always reads 0 (hosts, tests): all timings stay 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoCycleCounter;

impl CycleCounter for NoCycleCounter {
    #[inline]
    fn cycles(&mut self) -> u32 {
        0
    }
}

/// Any `FnMut() -> u32` is a counter.
impl<F: FnMut() -> u32> CycleCounter for F {
    #[inline]
    fn cycles(&mut self) -> u32 {
        self()
    }
}

/// Cycle statistics of one phase.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CycleStats {
    /// Cycles of the latest call.
    pub last: u32,
    /// Largest number of cycles since the last reset.
    pub max: u32,
    /// Calls measured since the last reset (saturating).
    pub count: u32,
}

impl CycleStats {
    fn record(&mut self, cycles: u32) {
        self.last = cycles;
        self.max = self.max.max(cycles);
        self.count = self.count.saturating_add(1);
    }
}

/// Cycles spent in the two phases of the timeline.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Timings {
    /// [`Controller::feedback`]: validation, the solver's feedback, output checks. A preparation
    /// that `feedback` has to do itself (no `start`/`prepare_next` before it) counts under
    /// `prepare`, not here.
    pub feedback: CycleStats,
    /// [`Controller::prepare_next`] (shift, reference window, the solver's prepare), and
    /// [`Controller::start`].
    pub prepare: CycleStats,
}

/// What went wrong in [`Controller::feedback`] (or [`Controller::step`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ControlErrorKind {
    /// The measured state had a NaN or infinite entry. The solver was called anyway and kept its
    /// previous plan (status `InvalidInput`); the input is that plan's first input.
    InvalidState,
    /// No reference window has ever been available, so the solver was never prepared and was not
    /// called; the input is the last applied one (initially 0 clamped into the bounds, i.e. hover
    /// for the standard inputs).
    NotPrepared,
    /// The solver's input had a NaN or infinite entry; each such entry was replaced by the last
    /// applied input's (a solver bug: docs/mpc.md promises a finite input).
    NonFiniteInput,
    /// The solver's input was outside `[U_MIN, U_MAX]` and was clamped (a solver bug: it should
    /// never happen).
    InputClamped,
    /// The solver reported `InvalidInput` for a finite state (a non-finite reference reached it).
    SolverInvalidInput,
    /// The solver reported `NumericalFailure` and kept its previous plan.
    NumericalFailure,
    /// The solver reported `OutOfEnvelope`: the measured state or the reference is far outside
    /// the model's envelope (a broken estimator?). The input is the solver's, finite and within
    /// the bounds, but not to be trusted.
    OutOfEnvelope,
    /// [`Controller::step`] only: feedback succeeded but the next preparation could not get a
    /// reference window and reused the previous one, shifted.
    Reference(ReferenceError),
}

impl core::fmt::Display for ControlErrorKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ControlErrorKind::InvalidState => f.write_str("non-finite state measurement"),
            ControlErrorKind::NotPrepared => f.write_str("no reference yet: solver not prepared"),
            ControlErrorKind::NonFiniteInput => f.write_str("solver returned a non-finite input"),
            ControlErrorKind::InputClamped => f.write_str("solver input outside the bounds, clamped"),
            ControlErrorKind::SolverInvalidInput => f.write_str("solver reported invalid input"),
            ControlErrorKind::NumericalFailure => f.write_str("solver reported a numerical failure"),
            ControlErrorKind::OutOfEnvelope => f.write_str("state or reference outside the model's envelope"),
            ControlErrorKind::Reference(e) => write!(f, "next reference window: {e}"),
        }
    }
}

/// An error of [`Controller::feedback`]. `solution.u0` is still an input to apply: finite and
/// within `[U_MIN, U_MAX]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControlError<R, const NU: usize> {
    /// What went wrong (the most serious problem if there were several).
    pub kind: ControlErrorKind,
    /// The sanitised solution; `status` is the solver's.
    pub solution: Solution<R, NU>,
}

impl<R, const NU: usize> ControlError<R, NU> {
    /// The input to apply anyway.
    pub fn input(&self) -> &[R; NU] {
        &self.solution.u0
    }
}

impl<R, const NU: usize> core::fmt::Display for ControlError<R, NU> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{} (solver status: {})", self.kind, self.solution.status)
    }
}

/// The real-time-iteration controller: a solver `S`, a reference source `Src` and a cycle counter
/// `C`, on a time grid t = t₀ + k·DT.
///
/// Timeline of one control period (see docs/runtime.md):
///
/// 1. measure x;
/// 2. [`feedback(x)`](Self::feedback) → u (low latency: the QP was prepared beforehand);
/// 3. apply u;
/// 4. [`prepare_next()`](Self::prepare_next): shift the solver, k += 1, build the reference window
///    for the new time, prepare the solver;
/// 5. wait for the next period.
///
/// [`step(x)`](Self::step) does 2 and 4 in one call (the input is then available only after the
/// preparation). [`start(t₀)`](Self::start) sets the time and prepares the first QP; without it the
/// first `feedback` prepares at t = 0 itself.
///
/// Reference windows are checked: if the source fails or gives a non-finite value, the previous
/// window shifted by one sample (last row repeated) is used instead and the error is returned by
/// `prepare_next`; if no window was ever available the solver is not prepared and `feedback`
/// returns [`ControlErrorKind::NotPrepared`].
///
/// `S` may be a `&mut` to a solver that lives elsewhere ([`MpcSolver`] is implemented for `&mut S`).
///
/// **Input delays.** With [`with_delay_compensation`](Self::with_delay_compensation) the solver
/// solves from the state predicted over the input delays (a [`StatePredictor`], normally a
/// [`DelayCompensator`](crate::DelayCompensator)) instead of the measured one; the controller
/// records every input it hands out in the predictor when time advances (`prepare_next`). The
/// default `P = NoDelay` solves from the measurement.
pub struct Controller<S, Src, R, const NX: usize, const NU: usize, const N1: usize, C = NoCycleCounter, P = NoDelay> {
    solver: S,
    reference: Src,
    counter: C,
    predictor: P,
    predicted: [R; NX],
    window: [[R; NX]; N1],
    window_valid: bool,
    t0: R,
    steps: u32,
    prepared: bool,
    last_input: [R; NU],
    last_prepare_status: Option<Status>,
    timings: Timings,
}

impl<S, Src, R, const NX: usize, const NU: usize, const N1: usize> Controller<S, Src, R, NX, NU, N1, NoCycleCounter>
where
    R: Real,
    S: MpcSolver<R, NX, NU, N1>,
    Src: ReferenceSource<R, NX, N1>,
{
    /// A controller at t = 0, not prepared, without timing.
    pub fn new(solver: S, reference: Src) -> Self {
        Self::with_counter(solver, reference, NoCycleCounter)
    }
}

impl<S, Src, R, C, const NX: usize, const NU: usize, const N1: usize> Controller<S, Src, R, NX, NU, N1, C>
where
    R: Real,
    S: MpcSolver<R, NX, NU, N1>,
    Src: ReferenceSource<R, NX, N1>,
    C: CycleCounter,
{
    /// A controller at t = 0, not prepared, timing with `counter`.
    pub fn with_counter(solver: S, reference: Src, counter: C) -> Self {
        Self {
            solver,
            reference,
            counter,
            predictor: NoDelay,
            predicted: [R::ZERO; NX],
            window: [[R::ZERO; NX]; N1],
            window_valid: false,
            t0: R::ZERO,
            steps: 0,
            prepared: false,
            last_input: Self::neutral_input(),
            last_prepare_status: None,
            timings: Timings::default(),
        }
    }
}

impl<S, Src, R, C, P, const NX: usize, const NU: usize, const N1: usize> Controller<S, Src, R, NX, NU, N1, C, P>
where
    R: Real,
    S: MpcSolver<R, NX, NU, N1>,
    Src: ReferenceSource<R, NX, N1>,
    C: CycleCounter,
    P: StatePredictor<R, NX, NU>,
{
    /// The same controller, solving from the state `predictor` predicts over the input delays
    /// (see the type's docs). Typically
    /// `DelayCompensator::new(krate::discrete_dynamics, krate::INPUT_DELAY_SAMPLES, hover)`.
    pub fn with_delay_compensation<P2: StatePredictor<R, NX, NU>>(
        self,
        predictor: P2,
    ) -> Controller<S, Src, R, NX, NU, N1, C, P2> {
        Controller {
            solver: self.solver,
            reference: self.reference,
            counter: self.counter,
            predictor,
            predicted: self.predicted,
            window: self.window,
            window_valid: self.window_valid,
            t0: self.t0,
            steps: self.steps,
            prepared: self.prepared,
            last_input: self.last_input,
            last_prepare_status: self.last_prepare_status,
            timings: self.timings,
        }
    }

    /// The solver's sample period.
    pub const DT: R = <S as MpcSolver<R, NX, NU, N1>>::DT;

    /// 0 clamped into `[U_MIN, U_MAX]`.
    fn neutral_input() -> [R; NU] {
        let mut u = [R::ZERO; NU];
        let bounds = S::U_MIN.into_iter().zip(S::U_MAX);
        for (ui, (lo, hi)) in u.iter_mut().zip(bounds) {
            *ui = ui.clamp_to(lo, hi);
        }
        u
    }

    /// Set the time to `t` (s), build its reference window and prepare the solver (no shift).
    /// Returns the solver's prepare status, or the reference error (then the previous window, if
    /// any, is used as it is).
    pub fn start(&mut self, t: R) -> Result<Status, ReferenceError> {
        self.t0 = t;
        self.steps = 0;
        self.timed_prepare(false)
    }

    /// Reset the solver's guess to the constant `x0`, `u` (e.g. the state at take-off and the hover
    /// input); the next `feedback` prepares again unless `start`/`prepare_next` come first.
    pub fn initialize(&mut self, x0: &[R; NX], u: &[R; NU]) {
        self.solver.initialize(x0, u);
        self.prepared = false;
    }

    /// The measurement step: solve the prepared QP for the measured state `x0`.
    ///
    /// `Ok` if the solver's status is `Solved`, `IterationCap` or `HessianRegularised` and its input
    /// needed no correction. Otherwise `Err`, whose `solution.u0` is still safe to apply (see
    /// [`ControlErrorKind`]). In both cases the input is finite and within `[U_MIN, U_MAX]`; a NaN
    /// cost is reported as +∞.
    pub fn feedback(&mut self, x0: &[R; NX]) -> Result<Solution<R, NU>, ControlError<R, NU>> {
        if !self.prepared {
            // Without a reference window the prepare status is irrelevant here: `prepared` says it.
            let _ = self.timed_prepare(false);
        }
        let start = self.counter.cycles();
        let result = self.feedback_prepared(x0);
        let cycles = self.counter.cycles().wrapping_sub(start);
        self.timings.feedback.record(cycles);
        result
    }

    fn feedback_prepared(&mut self, x0: &[R; NX]) -> Result<Solution<R, NU>, ControlError<R, NU>> {
        if !self.prepared {
            let solution = Solution {
                u0: self.last_input,
                status: Status::InvalidInput,
                qp_iterations: 0,
                cost: R::INFINITY,
            };
            return Err(ControlError {
                kind: ControlErrorKind::NotPrepared,
                solution,
            });
        }
        let state_ok = x0.iter().all(|v| v.is_finite());
        // A disturbance observer's update (crate::disturbance), before it predicts with it.
        self.predictor.measure(x0);
        // The state when this sample's input takes effect (x0 itself without delays).
        self.predicted = self.predictor.predict(x0);
        let mut solution = self.solver.feedback(&self.predicted);
        // The preparation is used up: a second feedback without prepare_next prepares again (an
        // SQP iteration at the same time).
        self.prepared = false;

        let mut non_finite = false;
        let mut clamped = false;
        let bounds = S::U_MIN.into_iter().zip(S::U_MAX);
        for ((u, last), (lo, hi)) in solution.u0.iter_mut().zip(self.last_input).zip(bounds) {
            if !u.is_finite() {
                non_finite = true;
                *u = last;
            }
            let c = u.clamp_to(lo, hi);
            if c != *u {
                clamped = true;
                *u = c;
            }
        }
        if solution.cost.is_nan() {
            solution.cost = R::INFINITY;
        }
        self.last_input = solution.u0;

        let kind = if !state_ok {
            Some(ControlErrorKind::InvalidState)
        } else if non_finite {
            Some(ControlErrorKind::NonFiniteInput)
        } else if clamped {
            Some(ControlErrorKind::InputClamped)
        } else {
            match solution.status {
                Status::InvalidInput => Some(ControlErrorKind::SolverInvalidInput),
                Status::NumericalFailure => Some(ControlErrorKind::NumericalFailure),
                Status::OutOfEnvelope => Some(ControlErrorKind::OutOfEnvelope),
                Status::Solved | Status::IterationCap | Status::HessianRegularised => None,
            }
        };
        match kind {
            None => Ok(solution),
            Some(kind) => Err(ControlError { kind, solution }),
        }
    }

    /// The preparation step, after the input was applied: shift the solver, advance the time by
    /// `DT`, build the reference window for the new time and prepare the solver. Returns the
    /// solver's prepare status, or the reference error (the previous window shifted by one sample is
    /// used instead; if there never was one, the solver stays unprepared).
    pub fn prepare_next(&mut self) -> Result<Status, ReferenceError> {
        self.timed_prepare(true)
    }

    /// `feedback(x0)` then `prepare_next()`. A reference error of the preparation turns an `Ok`
    /// feedback into `Err` with [`ControlErrorKind::Reference`] (the solution is valid); an error of
    /// the feedback takes precedence.
    pub fn step(&mut self, x0: &[R; NX]) -> Result<Solution<R, NU>, ControlError<R, NU>> {
        let feedback = self.feedback(x0);
        match (feedback, self.prepare_next()) {
            (Ok(solution), Err(e)) => Err(ControlError {
                kind: ControlErrorKind::Reference(e),
                solution,
            }),
            (feedback, _) => feedback,
        }
    }

    fn timed_prepare(&mut self, advance: bool) -> Result<Status, ReferenceError> {
        let start = self.counter.cycles();
        let result = self.prepare_inner(advance);
        let cycles = self.counter.cycles().wrapping_sub(start);
        self.timings.prepare.record(cycles);
        result
    }

    fn prepare_inner(&mut self, advance: bool) -> Result<Status, ReferenceError> {
        if advance {
            // The input handed out for the sample that just ended was applied over it.
            self.predictor.record(&self.last_input);
            self.solver.shift();
            self.steps = self.steps.saturating_add(1);
        }
        // The solver starts from the state when this sample's input takes effect, D samples
        // ahead: its reference window starts there too.
        let t = self.reference_time();
        let mut window = self.window;
        let built = match self.reference.window(t, Self::DT, &mut window) {
            Ok(()) if window.iter().flatten().all(|v| v.is_finite()) => Ok(()),
            Ok(()) => Err(ReferenceError::NonFinite),
            Err(e) => Err(e),
        };
        match built {
            Ok(()) => {
                self.window = window;
                self.window_valid = true;
            }
            Err(e) if !self.window_valid => {
                self.prepared = false;
                self.last_prepare_status = None;
                return Err(e);
            }
            Err(_) if advance => {
                // The previous window shifted by one sample, its last row repeated.
                self.window.rotate_left(1.min(N1));
                if let [.., second_last, last] = self.window.as_mut_slice() {
                    *last = *second_last;
                }
            }
            Err(_) => {}
        }
        if let Some(e) = self.predictor.disturbance() {
            // Refused only if not finite, which the observer never estimates.
            let _ = self.solver.set_disturbance(e);
        }
        let status = self.solver.prepare(&self.window);
        self.prepared = true;
        self.last_prepare_status = Some(status);
        built.map(|()| status)
    }

    /// The time (s) of the current sample: t₀ + k·DT.
    pub fn time(&self) -> R {
        self.t0 + R::from_u32(self.steps) * Self::DT
    }

    /// The time (s) of the first row of the reference window: t₀ + (k + D)·DT, D = the
    /// predictor's look-ahead (the largest input delay in samples; 0 without delay compensation).
    pub fn reference_time(&self) -> R {
        let lead = u32::try_from(self.predictor.lookahead()).unwrap_or(u32::MAX);
        self.t0 + R::from_u32(self.steps.saturating_add(lead)) * Self::DT
    }

    /// k: samples since `start` (or construction), saturating.
    pub fn step_count(&self) -> u32 {
        self.steps
    }

    /// The reference window the solver was last prepared with (rows r(t'), …, r(t' + N·DT),
    /// t' = [`reference_time`](Self::reference_time)).
    pub fn reference_window(&self) -> &[[R; NX]; N1] {
        &self.window
    }

    /// Whether a prepared QP is waiting for `feedback`.
    pub fn is_prepared(&self) -> bool {
        self.prepared
    }

    /// The solver's status of the last preparation (`None` before the first or if there was no
    /// window).
    pub fn last_prepare_status(&self) -> Option<Status> {
        self.last_prepare_status
    }

    /// The state the solver was last given by `feedback`: the measurement predicted over the input
    /// delays (the measurement itself without delay compensation); 0 before the first feedback.
    pub fn predicted_state(&self) -> &[R; NX] {
        &self.predicted
    }

    /// The state predictor (e.g. the [`DelayCompensator`](crate::DelayCompensator)).
    pub fn delay_compensator(&self) -> &P {
        &self.predictor
    }

    /// The state predictor, mutably (e.g. to `reset` its input history).
    pub fn delay_compensator_mut(&mut self) -> &mut P {
        &mut self.predictor
    }

    /// The last input `feedback` returned (initially 0 clamped into the bounds).
    pub fn last_input(&self) -> &[R; NU] {
        &self.last_input
    }

    /// Cycle counts of feedback and preparation.
    pub fn timings(&self) -> Timings {
        self.timings
    }

    /// Forget the cycle statistics.
    pub fn reset_timings(&mut self) {
        self.timings = Timings::default();
    }

    /// The solver.
    pub fn solver(&self) -> &S {
        &self.solver
    }

    /// The solver, mutably (changing its guess behind the controller's back invalidates nothing
    /// here; call `initialize` for a reset).
    pub fn solver_mut(&mut self) -> &mut S {
        &mut self.solver
    }

    /// The reference source.
    pub fn reference(&self) -> &Src {
        &self.reference
    }

    /// The reference source, mutably (e.g. to push setpoints).
    pub fn reference_mut(&mut self) -> &mut Src {
        &mut self.reference
    }

    /// The cycle counter, mutably.
    pub fn counter_mut(&mut self) -> &mut C {
        &mut self.counter
    }

    /// Take the controller apart (the predictor is dropped).
    pub fn into_parts(self) -> (S, Src, C) {
        (self.solver, self.reference, self.counter)
    }
}
