//! Tests that need the flight logs in `../shared` (beside the repository; CI has them): without
//! them such a test is *skipped*, and says so where it counts, not only in its captured stderr.
//!
//! [`skip`] records the test in `$CARGO_TARGET_TMPDIR/skipped/` (one file per test), which
//! `scripts/test.sh` counts into its summary line (`tests: P passed, S skipped, F failed`). With
//! `UAVGEN_REQUIRE_SHARED=1` (scripts/test.sh sets it when `../shared` exists) a missing file is a
//! failure instead: CI cannot skip silently. See docs/testing.md.

#![allow(dead_code)]

use std::path::Path;

/// The calling test is skipped because `absent` is missing; the caller returns right after.
/// Panics instead under `UAVGEN_REQUIRE_SHARED=1`.
pub fn skip(absent: &Path) {
    if std::env::var_os("UAVGEN_REQUIRE_SHARED").is_some_and(|v| v == "1") {
        panic!(
            "{} is absent, and UAVGEN_REQUIRE_SHARED=1 says the shared flight logs must be there",
            absent.display()
        );
    }
    let test = std::thread::current().name().unwrap_or("unknown").replace("::", "-");
    eprintln!(
        "SKIPPED: {} is absent (the shared flight logs live beside the repository)",
        absent.display()
    );
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("skipped");
    let _ = std::fs::create_dir_all(&dir);
    let _ = std::fs::write(
        dir.join(format!("{}-{test}", env!("CARGO_CRATE_NAME"))),
        format!("{}\n", absent.display()),
    );
}
