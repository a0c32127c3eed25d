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

/// The supervisor's thresholds (all in seconds or SI units, none tied to a rate), see
/// [`Controller::with_supervision`] and docs/runtime.md, "Supervisor".
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Supervision {
    /// A measurement repeated bit for bit while its velocity (states 6..9) is not zero for longer
    /// than this (s) is reported as [`ControlErrorKind::StaleMeasurement`]. Default 0.5 s.
    pub stale_after: f64,
    /// Length (s) of the saturation window of [`ControlErrorKind::NotConverging`]. Default 2 s.
    pub window: f64,
    /// The position error (states 0..3 against the reference) must shrink at least at this speed
    /// (m/s) over a window in which an input was at its bound in every sample; otherwise the loop
    /// is reported as not converging. Default 0.2 m/s.
    pub min_closing_speed: f64,
}

impl Default for Supervision {
    fn default() -> Self {
        Self {
            stale_after: 0.5,
            window: 2.0,
            min_closing_speed: 0.2,
        }
    }
}

/// What the supervisor currently sees ([`Controller::supervision`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SupervisorReport {
    /// How long (s) the measurement has been repeated unchanged with a non-zero velocity.
    pub held_for: f64,
    /// The measurement is stale (`held_for` > `stale_after`).
    pub stale: bool,
    /// Saturated without progress over the last window.
    pub not_converging: bool,
    /// Samples whose `prepare_next` had not happened when their measurement came
    /// ([`Controller::feedback_at`]), since construction (saturating).
    pub deadline_misses: u32,
    /// The position error (m) at the last feedback: ‖x₀..₃ − r₀..₃‖ against the first row of the
    /// reference window.
    pub position_error: f64,
}

/// Supervisor state.
#[derive(Clone, Copy, Debug, Default)]
struct SupervisorState<R, const NX: usize> {
    config: Supervision,
    report: SupervisorReport,
    /// The last measurement and the time (s) it first came.
    last: Option<([R; NX], f64)>,
    /// Start (time, error) of the current all-saturated window.
    saturated_since: Option<(f64, f64)>,
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
    /// Supervisor: the measurement has been repeated bit for bit, with a non-zero velocity, for
    /// longer than [`Supervision::stale_after`] (a stalled estimator). The input is the solver's for
    /// that old state: the loop is flying blind.
    StaleMeasurement,
    /// Supervisor: an input has been at its bound in every sample for
    /// [`Supervision::window`] and the position error has not shrunk by
    /// [`Supervision::min_closing_speed`] × the window over it: the loop is not getting back.
    NotConverging,
    /// [`Controller::feedback_at`]: the measurement is for a later sample than the one prepared
    /// (`prepare_next` was late or skipped): the controller caught up (shifted the solver and the
    /// reference to the measurement's sample and prepared there) before solving. Counted in
    /// [`Supervision`]'s `deadline_misses`.
    DeadlineMissed,
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
            ControlErrorKind::StaleMeasurement => f.write_str("stale measurement (repeated unchanged)"),
            ControlErrorKind::NotConverging => f.write_str("saturated and not converging to the reference"),
            ControlErrorKind::DeadlineMissed => f.write_str("deadline missed: caught up to the measurement's sample"),
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
    /// Time (s) of sample 0, in f64 whatever `R` is (f32 cannot count samples at Unix times).
    t0: f64,
    steps: u32,
    started: bool,
    supervisor: SupervisorState<R, NX>,
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
            t0: 0.0,
            steps: 0,
            started: false,
            supervisor: SupervisorState::default(),
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
            started: self.started,
            supervisor: self.supervisor,
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

    /// The same controller with the supervisor's thresholds `supervision` (docs/runtime.md,
    /// "Supervisor").
    pub fn with_supervision(mut self, supervision: Supervision) -> Self {
        self.supervisor.config = supervision;
        self
    }

    /// What the supervisor sees: stale measurement, saturation without progress, missed deadlines.
    pub fn supervision(&self) -> SupervisorReport {
        self.supervisor.report
    }

    /// Set the time to `t` (s; f64, or an `R` — any start time works with f32 crates, the
    /// controller keeps time in f64), build its reference window and prepare the solver.
    ///
    /// The first call does not shift the solver. A later call with a `t` up to N + 1 samples after
    /// the current time shifts the solver by the samples in between (rounded), as `prepare_next`
    /// would: calling `start(t)` every period is the same as `prepare_next`. Returns the solver's
    /// prepare status, or the reference error (then the previous window, if any, is used as it is).
    pub fn start(&mut self, t: impl Into<f64>) -> Result<Status, ReferenceError> {
        let t = t.into();
        let shifts = if self.started { self.samples_until(t) } else { 0 };
        self.t0 = t;
        self.steps = 0;
        self.started = true;
        self.timed_prepare(shifts, 0)
    }

    /// Whole samples (rounded) from the current sample's time to `t`; 0 if `t` is earlier, not
    /// finite or more than N + 1 samples later (then nothing of the old plan is worth shifting).
    fn samples_until(&self, t: f64) -> u32 {
        let samples = (t - self.time()) / Self::DT.to_f64();
        if samples.is_finite() && samples >= 0.5 && samples < (N1 as f64) + 1.5 {
            // `as` on a finite value in range: exact, no panic.
            (samples + 0.5) as u32
        } else {
            0
        }
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
    ///
    /// The supervisor ([`Supervision`]) turns an `Ok` into `Err` with
    /// [`StaleMeasurement`](ControlErrorKind::StaleMeasurement) or
    /// [`NotConverging`](ControlErrorKind::NotConverging) when the loop is not getting there.
    pub fn feedback(&mut self, x0: &[R; NX]) -> Result<Solution<R, NU>, ControlError<R, NU>> {
        self.feedback_inner(x0, false)
    }

    /// [`feedback`](Self::feedback) for a measurement taken at time `t` (s, the flight computer's
    /// clock, in f64 or `R`). If `t` falls on a later sample than the one prepared (the
    /// `prepare_next` of the samples in between came late or not at all), the controller first
    /// catches up — shifts the solver and moves the reference to the measurement's sample (rounded)
    /// and prepares there — counts the missed samples in [`SupervisorReport::deadline_misses`] and
    /// reports [`DeadlineMissed`](ControlErrorKind::DeadlineMissed) (the input is valid). A `t` on
    /// the prepared sample (or earlier) is an ordinary `feedback`; before any `start` or
    /// `prepare_next`, `feedback_at(t, x)` starts at t.
    pub fn feedback_at(&mut self, t: impl Into<f64>, x0: &[R; NX]) -> Result<Solution<R, NU>, ControlError<R, NU>> {
        let t = t.into();
        if !self.started {
            // The first measurement sets the time (as `start(t)`); a reference error leaves the
            // solver unprepared or on the previous window, which `feedback` reports.
            let _ = self.start(t);
        }
        let mut behind = 0;
        if self.started {
            let samples = (t - self.time()) / Self::DT.to_f64();
            if samples.is_finite() && samples >= 0.5 {
                // Saturating `as`: a huge gap is at most u32::MAX samples.
                behind = (samples + 0.5) as u32;
            }
        }
        if behind > 0 {
            let missed = &mut self.supervisor.report.deadline_misses;
            *missed = missed.saturating_add(behind);
            // More than N + 1 shifts leave nothing of the old plan: shift at most that many.
            let shifts = behind.min(u32::try_from(N1).unwrap_or(u32::MAX).saturating_add(1));
            // The reference error, if any, is the previous window's fallback (`prepare_next`'s).
            let _ = self.timed_prepare(shifts, behind);
        }
        self.feedback_inner(x0, behind > 0)
    }

    fn feedback_inner(&mut self, x0: &[R; NX], caught_up: bool) -> Result<Solution<R, NU>, ControlError<R, NU>> {
        if !self.prepared {
            // Without a reference window the prepare status is irrelevant here: `prepared` says it.
            let _ = self.timed_prepare(0, 0);
        }
        let start = self.counter.cycles();
        let mut result = self.feedback_prepared(x0);
        let cycles = self.counter.cycles().wrapping_sub(start);
        self.timings.feedback.record(cycles);
        if x0.iter().all(|v| v.is_finite()) && self.window_valid {
            self.supervise(x0, &result);
        }
        if let Ok(solution) = result {
            let report = self.supervisor.report;
            let kind = if report.stale {
                Some(ControlErrorKind::StaleMeasurement)
            } else if report.not_converging {
                Some(ControlErrorKind::NotConverging)
            } else if caught_up {
                Some(ControlErrorKind::DeadlineMissed)
            } else {
                None
            };
            if let Some(kind) = kind {
                result = Err(ControlError { kind, solution });
            }
        }
        result
    }

    /// Update the supervisor with a finite measurement and the feedback's result.
    fn supervise(&mut self, x0: &[R; NX], result: &Result<Solution<R, NU>, ControlError<R, NU>>) {
        let now = self.time();
        let config = self.supervisor.config;
        let state = &mut self.supervisor;
        // Stale: the same values again, while the velocity says the aircraft moves.
        let moving = x0.iter().skip(6).take(3).any(|v| *v != R::ZERO);
        match state.last {
            Some((last, since)) if last == *x0 && moving => {
                state.report.held_for = now - since;
            }
            _ => {
                state.last = Some((*x0, now));
                state.report.held_for = 0.0;
            }
        }
        state.report.stale = state.report.held_for > config.stale_after;
        // Position error against the first row of the window (states 0..3).
        let error = x0
            .iter()
            .zip(self.window.first().into_iter().flatten())
            .take(3)
            .map(|(x, r)| {
                let d: f64 = (*x - *r).into();
                d * d
            })
            .sum::<f64>();
        let error = libm::sqrt(error);
        state.report.position_error = error;
        let solution = match result {
            Ok(s) => s,
            Err(e) => &e.solution,
        };
        let saturated = solution
            .u0
            .iter()
            .zip(S::U_MIN.iter().zip(S::U_MAX.iter()))
            .any(|(u, (lo, hi))| {
                let margin = (*hi - *lo).abs() * R::from_f64(1e-6);
                (*u - *lo).abs() <= margin || (*hi - *u).abs() <= margin
            });
        if !saturated {
            state.saturated_since = None;
            state.report.not_converging = false;
        } else {
            match state.saturated_since {
                None => state.saturated_since = Some((now, error)),
                Some((since, error_then)) if now - since >= config.window => {
                    let progress = error_then - error;
                    state.report.not_converging = progress < config.min_closing_speed * (now - since);
                    state.saturated_since = Some((now, error));
                }
                Some(_) => {}
            }
        }
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
        self.started = true;
        self.timed_prepare(1, 1)
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

    /// Shift the solver `shifts` times, advance the sample count by `steps`, prepare.
    fn timed_prepare(&mut self, shifts: u32, steps: u32) -> Result<Status, ReferenceError> {
        let start = self.counter.cycles();
        for _ in 0..shifts {
            // The input handed out for the sample that just ended was applied over it.
            self.predictor.record(&self.last_input);
            self.solver.shift();
        }
        self.steps = self.steps.saturating_add(steps);
        let result = self.prepare_inner(shifts > 0);
        let cycles = self.counter.cycles().wrapping_sub(start);
        self.timings.prepare.record(cycles);
        result
    }

    fn prepare_inner(&mut self, advance: bool) -> Result<Status, ReferenceError> {
        // The solver starts from the state when this sample's input takes effect, D samples
        // ahead: its reference window starts there too.
        let t = self.reference_time();
        let mut window = self.window;
        let built = match self.reference.window_at(t, Self::DT.to_f64(), &mut window) {
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

    /// The time (s) of the current sample: t₀ + k·DT, in f64 whatever `R` is.
    pub fn time(&self) -> f64 {
        self.t0 + f64::from(self.steps) * Self::DT.to_f64()
    }

    /// The time (s) of the first row of the reference window: t₀ + (k + D)·DT, D = the
    /// predictor's look-ahead (the largest input delay in samples; 0 without delay compensation).
    pub fn reference_time(&self) -> f64 {
        let lead = u32::try_from(self.predictor.lookahead()).unwrap_or(u32::MAX);
        self.t0 + f64::from(self.steps.saturating_add(lead)) * Self::DT.to_f64()
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
