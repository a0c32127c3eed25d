//! Subcommands of the `uavgen` binary that drive the identification library.

pub mod identify;

use std::path::Path;

/// Write `text` to `path` atomically (temporary file + rename): nothing partial is left behind.
pub fn write_atomically(path: &Path, text: &str) -> Result<(), String> {
    let tmp = path.with_extension("uavgen-tmp");
    std::fs::write(&tmp, text).map_err(|e| format!("{}: {e}", tmp.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("{}: {e}", path.display())
    })
}
pub mod diagnose;
pub mod evaluate;
pub mod simulate;
pub mod track;
