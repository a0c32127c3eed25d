//! Subcommands of the `uavgen` binary that drive the library (identification, simulation,
//! closed loop, diagnosis).

pub mod diagnose;
pub mod envelope;
pub mod evaluate;
pub mod identify;
pub mod import;
pub mod progress;
pub mod simulate;
pub mod track;

use std::path::Path;

/// Write `text` to `path` atomically (temporary file in the same directory + rename): nothing
/// partial is left behind. The simulator's log writer does the same; one implementation serves both.
pub fn write_atomically(path: &Path, text: &str) -> Result<(), String> {
    uavgen::sim::write_atomically(path, text).map_err(|e| e.to_string())
}

/// The one `--force` rule of every command that writes a file: an existing output is replaced only
/// with `--force`. Checked before any work.
pub fn refuse_existing(path: &Path, force: bool) -> Result<(), String> {
    if path.exists() && !force {
        Err(format!("{}: exists; pass --force to overwrite it", path.display()))
    } else {
        Ok(())
    }
}
