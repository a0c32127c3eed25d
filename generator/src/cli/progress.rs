//! Progress of long work on stderr: bars where the amount of work is known, spinners where it is
//! not. Both are drawn by `indicatif` on stderr **only when stderr is a terminal** (its draw target
//! hides itself otherwise), so CI logs and redirected or piped stderr get none of it; `--quiet`
//! hides them on a terminal too. Results, warnings and errors are printed as always (docs/cli.md,
//! "Progress").

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

static QUIET: AtomicBool = AtomicBool::new(false);

/// `--quiet`: no bars or spinners at all.
pub fn set_quiet(quiet: bool) {
    QUIET.store(quiet, Ordering::Relaxed);
}

/// stderr if it is a terminal and `--quiet` was not given; hidden otherwise.
fn target() -> ProgressDrawTarget {
    if QUIET.load(Ordering::Relaxed) {
        ProgressDrawTarget::hidden()
    } else {
        // indicatif draws nothing on an stderr that is not a terminal.
        ProgressDrawTarget::stderr()
    }
}

/// A bar over `len` steps of `what`; call `finish_and_clear` when done.
pub fn bar(len: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(Some(len as u64), target());
    if let Ok(style) = ProgressStyle::with_template("{bar:40} {pos}/{len} {msg} ({elapsed})") {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    bar
}

/// A spinner with `what` until it is dropped (cleared then).
pub struct Spinner(ProgressBar);

/// Start a spinner for work of unknown length.
pub fn spinner(what: &str) -> Spinner {
    let bar = ProgressBar::with_draw_target(None, target());
    if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
        bar.set_style(style);
    }
    bar.set_message(what.to_string());
    if !bar.is_hidden() {
        bar.enable_steady_tick(Duration::from_millis(120));
    }
    Spinner(bar)
}

/// Run `work` under a spinner showing `what`.
pub fn with_spinner<T>(what: &str, work: impl FnOnce() -> T) -> T {
    let _spinner = spinner(what);
    work()
}

impl Drop for Spinner {
    fn drop(&mut self) {
        self.0.finish_and_clear();
    }
}
