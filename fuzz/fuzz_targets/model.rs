#![no_main]
//! `cargo +nightly fuzz run model` (docs/testing.md): the body is `uavgen::fuzzing::model`.
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| uavgen::fuzzing::model(data));
