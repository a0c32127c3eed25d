//! The PD hover model's MPC in f32 (N = 30 at 30 Hz) on the circular trajectory: single precision,
//! for Cortex-M4F/M7 parts whose FPU has no double precision.
#![no_std]
#![no_main]

use uavgen_firmware_example::{fly, init_core};

uavgen_runtime::mpc_adapter!(
    /// `pd_hover_f32::Mpc` as a `uavgen_runtime::MpcSolver`.
    struct PdHoverMpc(pd_hover_f32);
);

#[cortex_m_rt::entry]
fn main() -> ! {
    // A `&'static mut PdHoverMpc` (cortex-m-rt), in .bss.
    static mut SOLVER: PdHoverMpc = PdHoverMpc::new();

    init_core();
    let mut x0 = [0.0; pd_hover_f32::NX];
    x0[0] = 5.0;
    x0[2] = 6.0;
    fly(SOLVER, pd_hover_f32::discrete_dynamics, x0)
}
