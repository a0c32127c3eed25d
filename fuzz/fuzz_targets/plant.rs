#![no_main]
//! `cargo +nightly fuzz run plant` (docs/testing.md): the body is `uavgen::fuzzing::plant`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| uavgen::fuzzing::plant(data));
