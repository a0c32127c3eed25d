#![no_main]
//! `cargo +nightly fuzz run pysindy` (docs/testing.md): the body is `uavgen::fuzzing::pysindy`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| uavgen::fuzzing::pysindy(data));
