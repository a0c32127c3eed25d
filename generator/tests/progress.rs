//! Progress bars and spinners (docs/cli.md#progress) are drawn only on a terminal: piped stderr
//! carries none of them, and `--quiet` changes no output and no file.

mod common;

use common::{repo, stderr, uavgen};
use std::fs;
use std::path::Path;

/// No carriage return, no escape sequence, no spinner or bar glyph: what indicatif draws.
fn assert_no_progress(what: &str, text: &str) {
    for mark in ['\r', '\u{1b}', '█', '░', '⠁', '⠂', '⠄', '⡀', '⢀', '⠠', '⠐', '⠈'] {
        assert!(
            !text.contains(mark),
            "{what}: progress output ({mark:?}) in piped stderr:\n{text}"
        );
    }
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in fs::read_dir(&d).unwrap() {
            let p = entry.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().display().to_string(),
                    fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

#[test]
fn check_and_generate_pipe_no_progress_and_quiet_changes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    // `check` prints its summary on stdout; piped stderr stays empty (the spinner is not drawn).
    let plain = uavgen(&["check", "--model", "models/sindy_m100.json"]);
    assert!(plain.status.success(), "{}", stderr(&plain));
    assert_eq!(stderr(&plain), "");
    let quiet = uavgen(&["check", "--quiet", "--model", "models/sindy_m100.json"]);
    assert!(quiet.status.success(), "{}", stderr(&quiet));
    assert_eq!(quiet.stdout, plain.stdout);
    assert_eq!(stderr(&quiet), "");
    // Generation: the same files and messages with and without --quiet.
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let one = uavgen(&["--model", "models/pd_hover.json", "--out", a.to_str().unwrap()]);
    let two = uavgen(&[
        "--model",
        "models/pd_hover.json",
        "--out",
        b.to_str().unwrap(),
        "--quiet",
    ]);
    assert!(
        one.status.success() && two.status.success(),
        "{}{}",
        stderr(&one),
        stderr(&two)
    );
    assert_no_progress("generate", &stderr(&one));
    assert_eq!(stderr(&one), stderr(&two));
    assert_eq!(files(&a), files(&b));
    // The crate is the checked-in one: --quiet and the spinner change no byte of it.
    assert_eq!(files(&a), files(&repo().join("generated/pd_hover")));
}

#[test]
fn identify_and_evaluate_pipe_no_progress_and_quiet_changes_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    // A log simulated by `uavgen simulate` (itself under a spinner).
    let log = tmp.path().join("flight.csv");
    let o = uavgen(&[
        "simulate",
        "--plant",
        "plants/nominal.json",
        "--profile",
        "excite",
        "--duration",
        "40",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_no_progress("simulate", &stderr(&o));
    let mut outputs = Vec::new();
    for (i, quiet) in [false, true].into_iter().enumerate() {
        let out = tmp.path().join(format!("m{i}.json"));
        let mut args = vec![
            "identify",
            "--method",
            "sindy",
            "--log",
            log.to_str().unwrap(),
            "--sweep-values",
            "8,16",
            "--input-delay",
            "none",
            "--name",
            "m",
            "--out",
            out.to_str().unwrap(),
        ];
        if quiet {
            args.push("--quiet");
        }
        let o = uavgen(&args);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_no_progress("identify", &stderr(&o));
        let e = uavgen(&[
            "evaluate",
            "--model",
            out.to_str().unwrap(),
            "--log",
            log.to_str().unwrap(),
        ]);
        assert!(e.status.success(), "{}", stderr(&e));
        assert_no_progress("evaluate", &stderr(&e));
        outputs.push((fs::read(&out).unwrap(), stderr(&o), e.stdout));
    }
    // The same model file, the same messages, the same scores.
    assert_eq!(outputs[0], outputs[1]);
}
