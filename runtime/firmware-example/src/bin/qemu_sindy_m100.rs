//! The SINDy M100 MPC (f64) in QEMU (`qemu` feature; scripts/target_bench.sh): the closed loop on
//! the circle with two reference jumps, per-step instruction counts printed via semihosting.
#![no_std]
#![no_main]

use uavgen_firmware_example::qemu::{run, MAX_STEPS};

uavgen_runtime::mpc_adapter!(
    /// `sindy_m100::Mpc` as a `uavgen_runtime::MpcSolver`.
    struct SindyMpc(sindy_m100);
);

#[cortex_m_rt::entry]
fn main() -> ! {
    // Statics in .bss (cortex-m-rt hands them out as `&'static mut`), not on the measured stack.
    static mut SOLVER: SindyMpc = SindyMpc::new();
    static mut STEPS: [u32; MAX_STEPS] = [0; MAX_STEPS];

    // Hover at the circle's starting point (5, 0, 6).
    let mut x0 = [0.0; sindy_m100::NX];
    x0[0] = 5.0;
    x0[2] = 6.0;
    run("sindy_m100", SOLVER, sindy_m100::discrete_dynamics, x0, STEPS)
}
