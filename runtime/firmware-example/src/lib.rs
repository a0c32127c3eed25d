//! Shared part of the firmware example: the DWT cycle counter, the telemetry a debugger reads, and
//! the control loop (the circular trajectory, with the model itself as a stand-in for the aircraft).
//!
//! The binaries (`src/bin/*.rs`) only pick a generated crate, wrap its `Mpc` with
//! `uavgen_runtime::mpc_adapter!`, and call [`fly`].
#![no_std]
#![deny(unsafe_code)] // one exception: the painted-stack scan of the `qemu` feature

#[cfg(feature = "qemu")]
pub mod qemu;

use core::sync::atomic::{AtomicU32, Ordering::Relaxed};

use cortex_m::peripheral::DWT;
#[cfg(not(feature = "qemu"))]
use panic_halt as _;
use uavgen_runtime::{ControlErrorKind, Controller, CycleCounter, MpcSolver, Real, Trajectory};

/// Core clock in Hz: the STM32H743's reset clock (HSI, 64 MHz). A real board sets up its PLL
/// (up to 480 MHz) and puts the resulting frequency here.
pub const CPU_HZ: u32 = 64_000_000;

/// The Cortex-M DWT cycle counter (`CYCCNT`, wraps every 2³² cycles).
pub struct DwtCycles;

impl CycleCounter for DwtCycles {
    #[inline]
    fn cycles(&mut self) -> u32 {
        DWT::cycle_count()
    }
}

/// What the loop publishes for a debugger (`print uavgen_firmware_example::TELEMETRY`).
pub struct Telemetry {
    /// Control periods completed.
    pub steps: AtomicU32,
    /// Cycles of the latest / the slowest `feedback` (measurement in → input out).
    pub feedback_cycles_last: AtomicU32,
    /// See `feedback_cycles_last`.
    pub feedback_cycles_max: AtomicU32,
    /// Cycles of the latest / the slowest `prepare_next` (shift, reference, linearise, condense).
    pub prepare_cycles_last: AtomicU32,
    /// See `prepare_cycles_last`.
    pub prepare_cycles_max: AtomicU32,
    /// Feedback errors (the input was still applied: it is always finite and within bounds).
    pub feedback_errors: AtomicU32,
    /// The latest error: 0 none, 1 invalid state, 2 not prepared, 3 non-finite input, 4 input
    /// clamped, 5 solver invalid input, 6 numerical failure, 7 reference.
    pub last_error: AtomicU32,
    /// Reference-window errors of `prepare_next`.
    pub reference_errors: AtomicU32,
    /// Distance from the reference position, in mm.
    pub position_error_mm: AtomicU32,
    /// Periods whose computation overran DT.
    pub overruns: AtomicU32,
}

impl Telemetry {
    const fn new() -> Self {
        Self {
            steps: AtomicU32::new(0),
            feedback_cycles_last: AtomicU32::new(0),
            feedback_cycles_max: AtomicU32::new(0),
            prepare_cycles_last: AtomicU32::new(0),
            prepare_cycles_max: AtomicU32::new(0),
            feedback_errors: AtomicU32::new(0),
            last_error: AtomicU32::new(0),
            reference_errors: AtomicU32::new(0),
            position_error_mm: AtomicU32::new(0),
            overruns: AtomicU32::new(0),
        }
    }
}

/// The loop's published state.
pub static TELEMETRY: Telemetry = Telemetry::new();

fn error_code(kind: ControlErrorKind) -> u32 {
    match kind {
        ControlErrorKind::InvalidState => 1,
        ControlErrorKind::NotPrepared => 2,
        ControlErrorKind::NonFiniteInput => 3,
        ControlErrorKind::InputClamped => 4,
        ControlErrorKind::SolverInvalidInput => 5,
        ControlErrorKind::NumericalFailure => 6,
        ControlErrorKind::Reference(_) => 7,
        ControlErrorKind::OutOfEnvelope => 8,
        ControlErrorKind::StaleMeasurement => 9,
        ControlErrorKind::NotConverging => 10,
        ControlErrorKind::DeadlineMissed => 11,
    }
}

/// Enable the caches (the solver's matrices live in AXI SRAM) and the cycle counter.
pub fn init_core() {
    if let Some(mut cp) = cortex_m::Peripherals::take() {
        cp.SCB.enable_icache();
        cp.SCB.enable_dcache(&mut cp.CPUID);
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();
    }
}

/// Fly the circular trajectory forever: every DT, feedback → apply → prepare_next, with `plant`
/// (the generated `discrete_dynamics`) standing in for the aircraft and its sensors.
pub fn fly<S, R, const NX: usize, const NU: usize, const N1: usize>(
    solver: S,
    plant: fn(&[R; NX], &[R; NU]) -> [R; NX],
    x0: [R; NX],
) -> !
where
    R: Real,
    S: MpcSolver<R, NX, NU, N1>,
{
    let mut controller = Controller::with_counter(solver, Trajectory::Circular, DwtCycles);
    controller.initialize(&x0, &[R::ZERO; NU]);
    if controller.start(R::ZERO).is_err() {
        TELEMETRY.reference_errors.fetch_add(1, Relaxed);
    }
    let dt = <S as MpcSolver<R, NX, NU, N1>>::DT.to_f64();
    let period = (f64::from(CPU_HZ) * dt) as u32;
    let mut x = x0;
    let mut tick = DWT::cycle_count();
    loop {
        // 1. Measure (here: the simulated state). 2. Feedback: the low-latency part.
        let u = match controller.feedback(&x) {
            Ok(solution) => solution.u0,
            Err(error) => {
                TELEMETRY.feedback_errors.fetch_add(1, Relaxed);
                TELEMETRY.last_error.store(error_code(error.kind), Relaxed);
                error.solution.u0
            }
        };
        // 3. Apply the input: the stand-in aircraft moves one sample.
        x = plant(&x, &u);
        // 4. Prepare the next sample while waiting for it.
        if controller.prepare_next().is_err() {
            TELEMETRY.reference_errors.fetch_add(1, Relaxed);
        }

        let reference = controller.reference_window().first().copied().unwrap_or([R::ZERO; NX]);
        let mut e2 = R::ZERO;
        for (xi, ri) in x.iter().zip(reference.iter()).take(3) {
            e2 += (*xi - *ri) * (*xi - *ri);
        }
        let t = controller.timings();
        TELEMETRY.steps.store(controller.step_count(), Relaxed);
        TELEMETRY.feedback_cycles_last.store(t.feedback.last, Relaxed);
        TELEMETRY.feedback_cycles_max.store(t.feedback.max, Relaxed);
        TELEMETRY.prepare_cycles_last.store(t.prepare.last, Relaxed);
        TELEMETRY.prepare_cycles_max.store(t.prepare.max, Relaxed);
        TELEMETRY
            .position_error_mm
            .store((e2.sqrt().to_f64() * 1000.0) as u32, Relaxed);

        // 5. Wait for the next period (a real board would sleep until a timer interrupt).
        tick = tick.wrapping_add(period);
        if (DWT::cycle_count().wrapping_sub(tick) as i32) >= 0 {
            TELEMETRY.overruns.fetch_add(1, Relaxed);
            tick = DWT::cycle_count();
        }
        while (DWT::cycle_count().wrapping_sub(tick) as i32) < 0 {}
    }
}

/// The stack probes of a generated crate's Rust API (scripts/stack_bounds.sh): one
/// `#[inline(never)]` function `stack_probe_<fn>` per public function, each calling only that one,
/// and `stack_probe_all`, which calls them all (so that they are linked). scripts/stack_bound.py
/// bounds each probe's stack from the linked ELF's call graph; a probe's own frame is counted too,
/// so the bound is the function's plus a few words.
#[macro_export]
macro_rules! stack_probes {
    ($krate:ident) => {
        use $krate::{Mpc, Real, Solution, Status, N, NU, NX};

        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_new(m: &mut Mpc) {
            // The way to reset a solver at run time: from the constant (a memset); `*m = Mpc::new()`
            // may build the solver in this frame first.
            *m = const { Mpc::new() };
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_initialize(m: &mut Mpc, x0: &[Real; NX], u: &[Real; NU]) {
            m.initialize(x0, u)
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_set_guess(m: &mut Mpc, xs: &[[Real; NX]; N + 1], us: &[[Real; NU]; N]) -> bool {
            m.set_guess(xs, us)
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_set_disturbance(m: &mut Mpc, e: &[Real; NX]) -> bool {
            m.set_disturbance(e)
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_prepare(m: &mut Mpc, r: &[[Real; NX]; N + 1]) -> Status {
            m.prepare(r)
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_feedback(m: &mut Mpc, x0: &[Real; NX]) -> Solution {
            m.feedback(x0)
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_solve(m: &mut Mpc, x0: &[Real; NX], r: &[[Real; NX]; N + 1]) -> Solution {
            m.solve(x0, r)
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_shift(m: &mut Mpc) {
            m.shift()
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_planned_inputs(m: &Mpc, out: &mut [[Real; NU]; N]) {
            *out = *m.planned_inputs();
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_predicted_states(m: &Mpc, out: &mut [[Real; NX]; N + 1]) {
            *out = *m.predicted_states();
        }
        #[no_mangle]
        #[inline(never)]
        pub fn stack_probe_discrete_dynamics(x: &[Real; NX], u: &[Real; NU]) -> [Real; NX] {
            $krate::discrete_dynamics(x, u)
        }

        /// Every probe once, through `black_box` (nothing is folded away).
        #[inline(never)]
        pub fn stack_probe_all(m: &'static mut Mpc) {
            use core::hint::black_box;
            let x0 = black_box([0.0 as Real; NX]);
            let u = black_box([0.0 as Real; NU]);
            let r = black_box([x0; N + 1]);
            let mut us = [u; N];
            let mut xs = r;
            stack_probe_new(m);
            stack_probe_initialize(m, &x0, &u);
            black_box(stack_probe_set_guess(m, &r, &us));
            black_box(stack_probe_set_disturbance(m, &x0));
            black_box(stack_probe_prepare(m, &r));
            black_box(stack_probe_feedback(m, &x0));
            black_box(stack_probe_solve(m, &x0, &r));
            stack_probe_shift(m);
            stack_probe_planned_inputs(m, &mut us);
            stack_probe_predicted_states(m, &mut xs);
            black_box((us, xs));
            black_box(stack_probe_discrete_dynamics(&x0, &u));
        }
    };
}
