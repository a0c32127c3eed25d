//! Benchmarks live in the bench targets of this crate; see `cargo bench`.
