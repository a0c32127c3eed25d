#![no_main]
//! `cargo +nightly fuzz run import_mcap` (docs/testing.md): the body is `uavgen::fuzzing::import_mcap`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| uavgen::fuzzing::import_mcap(data));
