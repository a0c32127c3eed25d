//! `uavgen bench`: the worst-case benchmark of a generated crate, as a user
//! runs it on their own crate.
//!
//! It builds the harness of `benches/harness` (sources compiled into this
//! binary) in a scratch crate whose `solver` dependency points at the crate
//! under test, runs it pinned to one core, optionally counts instructions per
//! RTI step under callgrind, and — given the model file — times the generic
//! reference solver (interpreted model + clarabel) on the same scenario.

mod dims;
mod flash;
mod flops;
mod generic;
mod harness;

pub use dims::{read as read_crate_dims, CrateDims};
pub use flash::{measure as measure_flash, FirmwareSizes, TARGET as FLASH_TARGET};
pub use flops::{step_work, StepWork};
pub use generic::{run_generic, GenericTimings};
pub use harness::{
    adversarial_outcome, build_harness, count_adversarial, count_instructions, run_harness, HarnessResult,
    InstructionCounts, ADVERSARIAL_STEPS,
};

/// Options of `uavgen bench`.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// RTI steps per trajectory (3 trajectories).
    pub steps: usize,
    pub seed: u64,
    /// Steps per trajectory for the (slow) generic solver; 0 skips it.
    pub generic_steps: usize,
    /// Steps counted under callgrind; 0 skips it.
    pub instruction_steps: usize,
    /// Trials of the adversarial search counted under callgrind; 0 skips it.
    pub adversarial_trials: usize,
    /// Build with `-C target-cpu=<this>` (None: rustc's default for the host, x86-64 / SSE2).
    pub target_cpu: Option<String>,
    /// Where the scratch crate and its target directory live.
    pub work_dir: std::path::PathBuf,
}
