//! What the command-line tests share: the repository root and the `uavgen` binary run from it.

#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_owned()
}

/// Run `uavgen ARGS` in the repository root.
pub fn uavgen(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_uavgen"))
        .args(args)
        .current_dir(repo())
        .output()
        .expect("runs uavgen")
}

/// Its stderr as text.
pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// `uavgen simulate --plant PLANT --profile excite --duration SECONDS [--seed SEED] --out OUT`
/// (PLANT relative to the repository), which must succeed.
pub fn excite(plant: &str, seconds: &str, seed: Option<&str>, out: &std::path::Path) {
    let plant = repo().join(plant);
    let mut args = vec![
        "simulate",
        "--plant",
        plant.to_str().unwrap(),
        "--profile",
        "excite",
        "--duration",
        seconds,
        "--out",
        out.to_str().unwrap(),
    ];
    if let Some(seed) = seed {
        args.extend(["--seed", seed]);
    }
    let o = uavgen(&args);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// `uavgen identify --method METHOD --log LOG --out OUT EXTRA…`.
pub fn identify(method: &str, log: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "identify",
        "--method",
        method,
        "--log",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    uavgen(&args)
}
