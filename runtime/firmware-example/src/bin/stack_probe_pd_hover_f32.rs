//! Stack probes of `pd_hover_f32`'s Rust API (scripts/stack_bounds.sh): linked, not run on a board.
#![no_std]
#![no_main]

uavgen_firmware_example::stack_probes!(pd_hover_f32);

#[cortex_m_rt::entry]
fn main() -> ! {
    // The solver in .bss.
    static mut SOLVER: Mpc = Mpc::new();
    stack_probe_all(SOLVER);
    loop {
        core::hint::spin_loop();
    }
}
