//! The PD hover model's MPC in f32 in QEMU (`qemu` feature; scripts/target_bench.sh): the closed
//! loop on the circle with two reference jumps, per-step instruction counts printed via semihosting.
#![no_std]
#![no_main]

use uavgen_firmware_example::qemu::{run, MAX_STEPS};

uavgen_runtime::mpc_adapter!(
    /// `pd_hover_f32::Mpc` as a `uavgen_runtime::MpcSolver`.
    struct PdHoverMpc(pd_hover_f32);
);

#[cortex_m_rt::entry]
fn main() -> ! {
    // Statics in .bss (cortex-m-rt hands them out as `&'static mut`), not on the measured stack.
    static mut SOLVER: PdHoverMpc = PdHoverMpc::new();
    static mut STEPS: [u32; MAX_STEPS] = [0; MAX_STEPS];

    let mut x0 = [0.0; pd_hover_f32::NX];
    x0[0] = 5.0;
    x0[2] = 6.0;
    run("pd_hover_f32", SOLVER, pd_hover_f32::discrete_dynamics, x0, STEPS)
}
