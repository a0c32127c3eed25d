//! The SINDy M100 MPC (f64, N = 30 at 30 Hz) on the circular trajectory.
#![no_std]
#![no_main]

use uavgen_firmware_example::{fly, init_core};

uavgen_runtime::mpc_adapter!(
    /// `sindy_m100::Mpc` as a `uavgen_runtime::MpcSolver`.
    struct SindyMpc(sindy_m100);
);

#[cortex_m_rt::entry]
fn main() -> ! {
    // cortex-m-rt turns this into a `&'static mut SindyMpc`: the solver (about 290 KB) is a
    // zero-initialised static in .bss, never copied through the stack.
    static mut SOLVER: SindyMpc = SindyMpc::new();

    init_core();
    // Hover at the circle's starting point (5, 0, 6).
    let mut x0 = [0.0; sindy_m100::NX];
    x0[0] = 5.0;
    x0[2] = 6.0;
    fly(SOLVER, sindy_m100::discrete_dynamics, x0)
}
