//! The commands' shared code paths: what `uavgen <command>` and the Python package
//! (`generator/python/uavgen`, docs/python.md) both run, so that the two front ends give the same
//! results and the same messages. The front ends keep only argument parsing, progress display and
//! printing.

pub mod diagnose;
pub mod evaluate;
pub mod generate;
pub mod track;
