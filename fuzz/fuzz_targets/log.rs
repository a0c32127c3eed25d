#![no_main]
//! `cargo +nightly fuzz run log` (docs/testing.md): the body is `uavgen::fuzzing::log`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| uavgen::fuzzing::log(data));
