//! The closed loop on QEMU's MPS2 boards (`qemu` feature; scripts/target_bench.sh): the generated
//! solver through the runtime's [`Controller`], the model itself as the aircraft, the circle with
//! two reference jumps, for [`flight_seconds`] of simulated time; per-step instruction counts, the
//! stack high-water mark and the statuses printed through semihosting, and the exit status non-zero
//! when anything failed.
//!
//! Counting instructions: run QEMU with `-icount shift=0`, so that its virtual clock advances 1 ns
//! per executed instruction. The MPS2 boards clock SysTick's processor clock source at 25 MHz,
//! i.e. one SysTick tick per [`INSNS_PER_TICK`] instructions. [`calibrate`] checks that against a
//! loop of known length (`cortex_m::asm::delay`) before the loop runs.

use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_semihosting::{debug, hprintln};
use uavgen_runtime::{Controller, CycleCounter, MpcSolver, Real, ReferenceError, ReferenceSource, Trajectory};

/// QEMU MPS2: SysTick's processor clock is 25 MHz, i.e. 40 ns; under `-icount shift=0` one
/// instruction is 1 ns of virtual time.
pub const INSNS_PER_TICK: u32 = 40;

/// Simulated flight time in s: `UAVGEN_TARGET_SECONDS` at build time (whole seconds), 10 if unset.
pub const fn flight_seconds() -> u32 {
    match option_env!("UAVGEN_TARGET_SECONDS") {
        Some(s) => parse_u32(s),
        None => 10,
    }
}

const fn parse_u32(s: &str) -> u32 {
    let b = s.as_bytes();
    let mut i = 0;
    let mut v: u32 = 0;
    while i < b.len() {
        assert!(b[i].is_ascii_digit(), "UAVGEN_TARGET_SECONDS: whole seconds");
        v = v * 10 + (b[i] - b'0') as u32;
        i += 1;
    }
    v
}

/// The most control periods recorded (per-step counts are kept for the median).
pub const MAX_STEPS: usize = 8192;

/// SysTick (24 bits, counting down) extended to a 32-bit instruction counter. Correct as long as
/// it is read at least every 2²⁴ ticks (671 M instructions).
pub struct SysTickInsns {
    last: u32,
    total: u32,
}

impl SysTickInsns {
    /// Start SysTick on the processor clock, free running.
    pub fn start(mut syst: SYST) -> Self {
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00ff_ffff);
        syst.clear_current();
        syst.enable_counter();
        Self {
            last: SYST::get_current(),
            total: 0,
        }
    }
}

impl CycleCounter for SysTickInsns {
    #[inline]
    fn cycles(&mut self) -> u32 {
        let now = SYST::get_current();
        let ticks = self.last.wrapping_sub(now) & 0x00ff_ffff;
        self.last = now;
        self.total = self.total.wrapping_add(ticks * INSNS_PER_TICK);
        self.total
    }
}

/// Instructions measured for a `delay` loop of `2·(n+1)` instructions (`subs`; `bne`).
pub fn calibrate(counter: &mut SysTickInsns, n: u32) -> (u32, u32) {
    let t0 = counter.cycles();
    cortex_m::asm::delay(n);
    let t1 = counter.cycles();
    (2 * (n + 1), t1.wrapping_sub(t0))
}

/// The circle, shifted by `offset` m from `jump_s` s on and by `offset2` from `jump2_s` s on (kept
/// in the solver's precision: an f32 run does no f64 arithmetic in the measured `prepare_next`).
pub struct JumpingCircle<R> {
    /// Time of the first jump, s.
    pub jump_s: R,
    /// Position offset after the first jump, m.
    pub offset: [R; 3],
    /// Time of the second jump, s.
    pub jump2_s: R,
    /// Position offset after the second jump, m.
    pub offset2: [R; 3],
}

impl<R: Real> JumpingCircle<R> {
    fn offset_at(&self, t: R) -> [R; 3] {
        if t >= self.jump2_s {
            self.offset2
        } else if t >= self.jump_s {
            self.offset
        } else {
            [R::ZERO; 3]
        }
    }
}

impl<R: Real, const NX: usize, const N1: usize> ReferenceSource<R, NX, N1> for JumpingCircle<R> {
    fn window(&mut self, t0: R, dt: R, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError> {
        <Trajectory as ReferenceSource<R, NX, N1>>::window(&mut Trajectory::Circular, t0, dt, out)?;
        let mut t = t0;
        for row in out.iter_mut() {
            for (v, o) in row.iter_mut().zip(self.offset_at(t)) {
                *v += o;
            }
            t += dt;
        }
        Ok(())
    }
}

/// The highest stack use since reset, in bytes: cortex-m-rt's `paint-stack` fills the RAM between
/// the end of .bss (`_stack_end`) and the initial stack pointer (`_stack_start`) with 0xCCCCCCCC
/// at reset; the lowest word no longer painted marks the deepest the stack has been.
#[allow(unsafe_code)]
pub fn stack_high_water() -> u32 {
    extern "C" {
        static _stack_end: u32;
        static _stack_start: u32;
    }
    // Only the linker symbols' addresses are taken; the words read lie between them, in RAM that
    // the linker script reserves for the stack (aligned, readable).
    let (lo, hi) = (
        core::ptr::addr_of!(_stack_end) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    );
    let mut p = (lo + 3) & !3;
    // SAFETY: see above; `p` stays within [lo, hi).
    while p < hi && unsafe { core::ptr::read_volatile(p as *const u32) } == 0xCCCC_CCCC {
        p += 4;
    }
    (hi - p) as u32
}

/// Run the closed loop for [`flight_seconds`] and exit QEMU through semihosting: status 0 when
/// every feedback and every reference window succeeded and the calibration matched, 1 otherwise.
/// `steps` is working storage for the per-step counts (a static of the binary, not the stack).
pub fn run<S, R, const NX: usize, const NU: usize, const N1: usize>(
    label: &str,
    solver: S,
    plant: fn(&[R; NX], &[R; NU]) -> [R; NX],
    x0: [R; NX],
    steps: &mut [u32; MAX_STEPS],
) -> !
where
    R: Real,
    S: MpcSolver<R, NX, NU, N1>,
{
    let mut failures = 0u32;
    let Some(cp) = cortex_m::Peripherals::take() else {
        exit(false)
    };
    let mut counter = SysTickInsns::start(cp.SYST);
    let (expected, measured) = calibrate(&mut counter, 1_000_000);
    // The counter's resolution is one tick (40 instructions) at each end.
    let calibration_ok = measured.abs_diff(expected) <= 4 * INSNS_PER_TICK;
    hprintln!(
        "calibration: delay loop of {} instructions counted as {}",
        expected,
        measured
    );
    if !calibration_ok {
        hprintln!("calibration FAILED: is QEMU running with -icount shift=0?");
        failures += 1;
    }

    let dt = <S as MpcSolver<R, NX, NU, N1>>::DT.to_f64();
    let seconds = f64::from(flight_seconds());
    let n_steps = ((seconds / dt + 0.5) as usize).min(MAX_STEPS);
    // Jumps of 1 m (x, then y) at a third and at two thirds of the flight, on a sample.
    let (k1, k2) = (n_steps / 3, 2 * n_steps / 3);
    let (one, zero) = (R::from_f64(1.0), R::ZERO);
    let reference = JumpingCircle {
        jump_s: R::from_f64((k1 as f64 - 0.5) * dt),
        offset: [one, zero, zero],
        jump2_s: R::from_f64((k2 as f64 - 0.5) * dt),
        offset2: [zero, one, zero],
    };
    let mut controller = Controller::with_counter(solver, reference, counter);
    controller.initialize(&x0, &[R::ZERO; NU]);
    if controller.start(R::ZERO).is_err() {
        failures += 1;
    }
    let (mut feedback_max, mut prepare_max) = (0u32, 0u32);
    let (mut feedback_errors, mut reference_errors) = (0u32, 0u32);
    let mut x = x0;
    let mut error_end = 0.0f64;
    let mut error_max_settled = 0.0f64;
    for (k, slot) in steps.iter_mut().take(n_steps).enumerate() {
        let u = match controller.feedback(&x) {
            Ok(solution) => solution.u0,
            Err(error) => {
                if feedback_errors == 0 {
                    hprintln!("feedback error at t = {} s: {}", controller.time().to_f64(), error.kind);
                }
                feedback_errors += 1;
                error.solution.u0
            }
        };
        let feedback = controller.timings().feedback.last;
        x = plant(&x, &u);
        if controller.prepare_next().is_err() {
            reference_errors += 1;
        }
        let prepare = controller.timings().prepare.last;
        feedback_max = feedback_max.max(feedback);
        prepare_max = prepare_max.max(prepare);
        *slot = feedback.saturating_add(prepare);

        let reference = controller.reference_window().first().copied().unwrap_or([R::ZERO; NX]);
        let mut e2 = 0.0f64;
        for (xi, ri) in x.iter().zip(reference.iter()).take(3) {
            let d = (*xi - *ri).to_f64();
            e2 += d * d;
        }
        error_end = libm_sqrt(e2);
        if !x.iter().all(|v| v.is_finite()) {
            failures += 1;
            break;
        }
        // Tracking error just before each jump (the loop has settled by then).
        if k + 1 == k1 || k + 1 == k2 {
            error_max_settled = error_max_settled.max(error_end);
        }
    }
    let counts = &mut steps[..n_steps];
    counts.sort_unstable();
    let median = counts.get(n_steps / 2).copied().unwrap_or(0);
    let max = counts.last().copied().unwrap_or(0);
    let stack = stack_high_water();
    failures += feedback_errors + reference_errors;
    hprintln!(
        "RESULT {} steps={} dt={} step_median={} step_max={} feedback_max={} prepare_max={} stack_bytes={} \
         feedback_errors={} reference_errors={} error_before_jumps_m={:.3} error_end_m={:.3}",
        label,
        n_steps,
        dt,
        median,
        max,
        feedback_max,
        prepare_max,
        stack,
        feedback_errors,
        reference_errors,
        error_max_settled,
        error_end
    );
    exit(failures == 0)
}

fn libm_sqrt(v: f64) -> f64 {
    <f64 as Real>::sqrt(v)
}

/// A panic (none is expected: the no-panic check of scripts/test.sh covers the firmware binaries)
/// leaves QEMU with status 1 instead of hanging until the script's timeout.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("panic: {}", info);
    exit(false)
}

/// Leave QEMU with status 0 (`ok`) or 1.
pub fn exit(ok: bool) -> ! {
    debug::exit(if ok { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
    loop {
        core::hint::spin_loop();
    }
}
