//! Puts the memory layout (`memory/stm32h743.x`, or `memory/mps2.x` with the `qemu` feature) on the linker's search path, checks the target, and passes `-Tlink.x` when
//! `.cargo/config.toml` did not (cargo reads that file only when run in this directory or below;
//! from the repository root, `--manifest-path … --target thumbv7em-none-eabihf` builds through
//! this script alone).

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let target = env::var("TARGET").unwrap_or_default();
    if !target.starts_with("thumbv7em-") {
        panic!(
            "uavgen-firmware-example is firmware for thumbv7em-none-eabihf, not {target}: run cargo in \
             runtime/firmware-example, or add `--target thumbv7em-none-eabihf`"
        );
    }

    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    // As `memory.x` (the name cortex-m-rt's link.x includes) in OUT_DIR only: a memory.x in the
    // package root would be found first, whatever the feature. The `qemu` feature links for QEMU's
    // MPS2 boards instead of the STM32H743.
    let memory = if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        "memory/mps2.x"
    } else {
        "memory/stm32h743.x"
    };
    fs::copy(memory, out.join("memory.x")).expect("copy the memory layout");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory");
    println!("cargo:rerun-if-changed=build.rs");

    let rustflags = env::var("CARGO_ENCODED_RUSTFLAGS").unwrap_or_default();
    if !rustflags.split('\x1f').any(|flag| flag.contains("-Tlink.x")) {
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
    }
}
