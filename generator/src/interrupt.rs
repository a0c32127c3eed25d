//! Outputs that survive an interruption: nothing partial is left behind after Ctrl-C (SIGINT),
//! SIGTERM or SIGHUP, and what a killed run (SIGKILL, power loss) left is cleaned by the next one.
//!
//! Every output of uavgen is put in place in one short critical section — a file written to a
//! hidden temporary beside it and renamed ([`crate::sim::write_atomically`]), a generated crate
//! staged in a hidden directory and swapped in ([`crate::codegen::write`]), a plot or report
//! directory written whole. Each holds [`output_lock`] for that section. The binary's signal
//! handler ([`on_signal`]) takes the same lock before it exits, so a signal either arrives
//! before a section (nothing of it exists yet) or waits for it to finish (the output is whole,
//! its temporaries removed). The handler then exits with status 130.
//!
//! A process that is killed outright cannot run a handler: its hidden temporaries carry its
//! process id (`.NAME.PID.uavgen-tmp`, `.NAME.uavgen-staging-PID`, `.NAME.uavgen-old-PID`), and
//! [`stale_pid`] tells the next run writing the same output that their owner is gone, so it
//! removes them (and puts a set-aside crate back where its swap was cut short).

use std::path::Path;
use std::sync::{Mutex, MutexGuard};

static OUTPUT: Mutex<()> = Mutex::new(());

/// The exit status after an interrupting signal (128 + SIGINT, as a shell reports Ctrl-C).
pub const INTERRUPTED_STATUS: i32 = 130;

/// Held while an output is put in place; a signal's handler waits for it.
pub fn output_lock() -> MutexGuard<'static, ()> {
    // A panic while the lock was held leaves no partial output either (the section's own
    // cleanup ran or the temporaries carry the pid): the poison carries no meaning here.
    OUTPUT.lock().unwrap_or_else(|e| e.into_inner())
}

/// What the binary's handler does on SIGINT, SIGTERM or SIGHUP: wait for an output being put in
/// place, say so, and exit with [`INTERRUPTED_STATUS`] without writing anything more.
pub fn on_signal() -> ! {
    let _guard = output_lock();
    eprintln!("interrupted: stopped before writing anything further (no partial output is left)");
    std::process::exit(INTERRUPTED_STATUS)
}

/// The process id in a hidden temporary's name made by `prefix`PID`suffix`, if that process no
/// longer runs (Linux: no `/proc/PID`). `None` for another name, a running process, the current
/// one, or where liveness cannot be told.
pub fn stale_pid(name: &str, prefix: &str, suffix: &str) -> Option<u32> {
    let pid: u32 = name.strip_prefix(prefix)?.strip_suffix(suffix)?.parse().ok()?;
    if pid == std::process::id() || !Path::new("/proc/self").exists() {
        return None;
    }
    (!Path::new(&format!("/proc/{pid}")).exists()).then_some(pid)
}

/// Remove `dir`'s entries named `prefix`PID`suffix` whose process is gone (files or directories).
/// Best effort: what cannot be read or removed is left.
pub fn remove_stale(dir: &Path, prefix: &str, suffix: &str) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if stale_pid(&name, prefix, suffix).is_some() {
            let path = entry.path();
            let _ = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_names_are_told_by_their_pid() {
        // pid 0 is never a user process; the current process is never stale.
        let me = std::process::id();
        assert_eq!(
            stale_pid(&format!(".a.uavgen-staging-{me}"), ".a.uavgen-staging-", ""),
            None
        );
        assert_eq!(stale_pid(".a.uavgen-staging-x", ".a.uavgen-staging-", ""), None);
        assert_eq!(stale_pid(".b.uavgen-staging-4000000", ".a.uavgen-staging-", ""), None);
        if Path::new("/proc/self").exists() {
            // Above the kernel's pid_max (4194304): no such process.
            assert_eq!(
                stale_pid(".log.csv.4194305.uavgen-tmp", ".log.csv.", ".uavgen-tmp"),
                Some(4194305)
            );
        }
    }

    #[test]
    fn remove_stale_leaves_live_and_foreign_entries() {
        if !Path::new("/proc/self").exists() {
            return;
        }
        let dir = tempfile::tempdir().unwrap();
        let me = std::process::id();
        for name in [
            ".out.uavgen-staging-4194305".to_string(),
            format!(".out.uavgen-staging-{me}"),
            "out".to_string(),
        ] {
            std::fs::create_dir(dir.path().join(name)).unwrap();
        }
        remove_stale(dir.path(), ".out.uavgen-staging-", "");
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, vec![format!(".out.uavgen-staging-{me}"), "out".to_string()]);
    }
}
