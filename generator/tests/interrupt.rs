//! Interrupted runs leave nothing behind (docs/cli.md, "Files"; `uavgen::interrupt`): 100 runs of
//! generate, identify and evaluate are interrupted by SIGINT or SIGTERM at pseudo-random moments;
//! after each the output is either absent or whole, and no hidden temporary is left. A run killed
//! outright (no handler) is cleaned up by the next one; a symlinked `--out` is followed.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_uavgen")
}

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(rel)
}

/// The entries of `dir` (names, sorted), recursively as relative paths.
fn tree(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, rel: &Path, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(root.join(rel)) else {
            return;
        };
        for e in entries.flatten() {
            let r = rel.join(e.file_name());
            out.push(r.display().to_string());
            if e.path().is_dir() && !e.path().is_symlink() {
                walk(root, &r, out);
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, Path::new(""), &mut out);
    out.sort();
    out
}

/// A small deterministic generator (the test's moments are reproducible).
struct Lcg(u64);
impl Lcg {
    fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Run `args` in `dir`, interrupt it with `signal` after `after`, and wait for it.
fn interrupt(dir: &Path, args: &[&str], signal: &str, after: Duration) {
    let mut child = Command::new(bin())
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("uavgen starts");
    let start = Instant::now();
    while start.elapsed() < after {
        if child.try_wait().expect("wait").is_some() {
            return;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let _ = Command::new("kill").args([signal, &child.id().to_string()]).status();
    let _ = child.wait();
}

/// How long `args` takes in `dir` when not interrupted, and the tree it leaves.
fn full_run(dir: &Path, args: &[&str]) -> (Duration, Vec<String>) {
    let start = Instant::now();
    let out = Command::new(bin())
        .args(args)
        .current_dir(dir)
        .output()
        .expect("uavgen runs");
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (start.elapsed(), tree(dir))
}

#[cfg(unix)]
#[test]
fn a_hundred_interrupts_leave_nothing_behind() {
    let work = tempfile::tempdir().unwrap();
    let log = work.path().join("flight.csv");
    let status = Command::new(bin())
        .args(["simulate", "--plant"])
        .arg(repo("plants/nominal.json"))
        .args(["--duration", "20", "--seed", "2", "--out"])
        .arg(&log)
        .output()
        .unwrap();
    assert!(status.status.success());
    let model = repo("models/pd_hover.json");
    let (model, log) = (model.to_str().unwrap(), log.to_str().unwrap());
    let cases: [(&str, Vec<&str>, usize); 3] = [
        (
            "generate",
            vec!["--model", model, "--horizon", "30", "--out", "crate"],
            40,
        ),
        (
            "identify",
            vec![
                "identify",
                "--method",
                "pd",
                "--log",
                log,
                "--input-delay",
                "none",
                "--out",
                "m.json",
            ],
            30,
        ),
        (
            "evaluate",
            vec![
                "evaluate", "--model", model, "--log", log, "--plots", "plots", "--json", "e.json",
            ],
            30,
        ),
    ];
    let mut rng = Lcg(2026);
    let mut outcomes = [0usize; 2];
    for (name, args, runs) in &cases {
        let reference = tempfile::tempdir().unwrap();
        let (took, whole) = full_run(reference.path(), args);
        for run in 0..*runs {
            let dir = tempfile::tempdir().unwrap();
            let after = took.mul_f64(1.2 * rng.unit());
            let signal = if run % 3 == 2 { "-TERM" } else { "-INT" };
            interrupt(dir.path(), args, signal, after);
            let left = tree(dir.path());
            assert!(
                left.iter().all(|e| !e.split('/').any(|c| c.starts_with('.'))),
                "{name}, {signal} after {after:?}: hidden temporaries left: {left:?}"
            );
            // Each top-level output is absent or whole (every file the full run writes under it).
            for top in whole.iter().filter(|e| !e.contains('/')) {
                let under = |t: &[String]| -> Vec<String> {
                    t.iter()
                        .filter(|e| *e == top || e.starts_with(&format!("{top}/")))
                        .cloned()
                        .collect()
                };
                let got = under(&left);
                assert!(
                    got.is_empty() || got == under(&whole),
                    "{name}, {signal} after {after:?}: {top} is partial: {got:?}"
                );
            }
            outcomes[usize::from(left.is_empty())] += 1;
        }
    }
    // The moments spread over the runs: some were interrupted early, some finished.
    assert!(
        outcomes[0] > 0 && outcomes[1] > 0,
        "outcomes (written, nothing) {outcomes:?}"
    );
}

#[cfg(target_os = "linux")]
#[test]
fn a_killed_runs_temporaries_are_cleaned_by_the_next_run() {
    let dir = tempfile::tempdir().unwrap();
    let model = repo("models/pd_hover.json");
    let run = || {
        let out = Command::new(bin())
            .args(["--model", model.to_str().unwrap(), "--horizon", "10", "--out", "crate"])
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    };
    run();
    // A kill between the swap's two renames: the crate set aside, none in place, and a staging
    // directory (pid above the kernel's pid_max: no such process).
    std::fs::rename(dir.path().join("crate"), dir.path().join(".crate.uavgen-old-4194305")).unwrap();
    std::fs::create_dir(dir.path().join(".crate.uavgen-staging-4194305")).unwrap();
    std::fs::write(dir.path().join(".log.csv.4194305.uavgen-tmp"), "t,x").unwrap();
    run();
    let top = |d: &Path| -> Vec<String> { tree(d).into_iter().filter(|e| !e.contains('/')).collect() };
    assert_eq!(top(dir.path()), [".log.csv.4194305.uavgen-tmp", "crate"]);
    // A file writer removes the leftover temporaries of the file it writes.
    let out = Command::new(bin())
        .args(["simulate", "--plant"])
        .arg(repo("plants/nominal.json"))
        .args(["--duration", "1", "--out", "log.csv"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(top(dir.path()), ["crate", "log.csv"]);
}

#[cfg(unix)]
#[test]
fn a_symlinked_out_is_followed() {
    let dir = tempfile::tempdir().unwrap();
    let real = dir.path().join("real");
    std::fs::create_dir(&real).unwrap();
    std::os::unix::fs::symlink(&real, dir.path().join("link")).unwrap();
    let model = repo("models/pd_hover.json");
    let out = Command::new(bin())
        .args(["--model", model.to_str().unwrap(), "--horizon", "10", "--out", "link"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(dir.path().join("link").is_symlink(), "the link was replaced");
    assert!(
        real.join("Cargo.toml").is_file(),
        "the crate is not where the link points"
    );
    assert_eq!(tree(dir.path()).iter().filter(|e| e.starts_with('.')).count(), 0);
}
