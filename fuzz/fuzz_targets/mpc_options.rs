#![no_main]
//! `cargo +nightly fuzz run mpc_options` (docs/testing.md): the body is `uavgen::fuzzing::mpc_options`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| uavgen::fuzzing::mpc_options(data));
