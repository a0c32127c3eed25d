//! `uavgen bench` as a user runs it on a checked-in crate: the step's arithmetic agrees with
//! `uavgen check`, the instruction counts split into prepare and feedback, and a model file that
//! is not the crate's is refused.

mod common;

use common::{stderr, uavgen};
use std::path::Path;
use std::process::Command;

/// The last number on the line of `text` that contains `marker`.
fn number_after(text: &str, marker: &str) -> u64 {
    let line = text
        .lines()
        .find(|l| l.contains(marker))
        .unwrap_or_else(|| panic!("no line with {marker:?} in:\n{text}"));
    line.rsplit(|c: char| !c.is_ascii_digit())
        .find(|w| !w.is_empty())
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("no number in {line:?}"))
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn has_valgrind() -> bool {
    Command::new("valgrind")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// pd_hover (condensed, f64): bench's multiply-adds are check's, 2 flops each; with valgrind the
/// prepare and feedback counts are positive and below the whole step's.
#[test]
fn bench_counts_the_work_check_reports_and_splits_the_instructions() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("bench.json");
    let check = uavgen(&["check", "--model", "models/pd_hover.json", "--horizon", "30"]);
    assert!(check.status.success(), "{}", stderr(&check));
    let check_text = String::from_utf8_lossy(&check.stdout).into_owned();
    let macs = number_after(&check_text, "multiply-adds per RTI step without the QP's iterations");
    // The figure without the structural specialisation is printed last on that line; the
    // specialised one comes first.
    let line = check_text
        .lines()
        .find(|l| l.contains("multiply-adds per RTI step without the QP's iterations"))
        .unwrap();
    let specialised: u64 = line
        .split(": ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|w| w.parse().ok())
        .unwrap_or_else(|| panic!("{line}"));
    assert!(specialised <= macs && specialised > 0, "{line}");

    let valgrind = has_valgrind();
    let work_dir = tmp.path().join("work");
    let mut args = vec![
        "bench",
        "--crate",
        "generated/pd_hover",
        "--model",
        "models/pd_hover.json",
        "--steps",
        "2",
        "--generic-steps",
        "0",
        "--work-dir",
        work_dir.to_str().unwrap(),
        "--json",
        out.to_str().unwrap(),
    ];
    if valgrind {
        args.extend_from_slice(&["--instructions", "2"]);
    }
    // scripts/test.sh installs the Cortex-M target; a plain `cargo test` may not have it.
    let thumb = Command::new("rustup")
        .args(["target", "list", "--installed"])
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("thumbv7em-none-eabihf"));
    if thumb {
        args.push("--flash");
    }
    let o = uavgen(&args);
    assert!(o.status.success(), "{}", stderr(&o));
    let report = json(&out);
    let work = &report["work"];
    let m = &work["multiply_adds"];
    let sum: u64 = ["linearisation", "condensing", "cholesky", "feedback"]
        .iter()
        .map(|k| m[k].as_u64().unwrap())
        .sum();
    assert_eq!(
        sum, specialised,
        "bench's multiply-adds {m} against check's {specialised}"
    );
    assert_eq!(
        work["total_flops_without_qp_iterations"].as_u64(),
        Some(2 * specialised)
    );
    assert!(work["prepare_gflops_at_median"].as_f64().unwrap() > 0.0);
    if valgrind {
        let c = &report["instructions"];
        let (median, max) = (c["median"].as_u64().unwrap(), c["max"].as_u64().unwrap());
        let (p, f) = (&c["prepare"], &c["feedback"]);
        assert_eq!(c["steps"].as_u64(), Some(6), "{c}");
        for phase in [p, f] {
            let (pm, px) = (phase[0].as_u64().unwrap(), phase[1].as_u64().unwrap());
            assert!(pm > 0 && pm <= px && px <= max, "{c}");
        }
        // Every step is its prepare plus its feedback, so the largest step is at most the sum of
        // the largest phases and at least either of them.
        let (pmax, fmax) = (p[1].as_u64().unwrap(), f[1].as_u64().unwrap());
        assert!(max <= pmax + fmax && max >= pmax.max(fmax) && median <= max, "{c}");
        assert!(work["prepare_flops_per_instruction"].as_f64().unwrap() > 0.0);
    } else {
        eprintln!("valgrind not found: the instruction split is not checked");
    }
    if thumb {
        // The solver is a static in .bss, none of it in flash-copied .data; its RAM is the
        // solver's size (usize is 4 bytes on the Cortex-M, 8 here) plus the runtime's few bytes.
        let fw = &report["firmware"];
        let size_of = report["generated"]["size_of_mpc"].as_u64().unwrap();
        let (ram, flash) = (fw["ram"].as_u64().unwrap(), fw["flash"].as_u64().unwrap());
        assert_eq!(fw["sections"]["data"].as_u64(), Some(0), "{fw}");
        assert!(
            ram + 2048 >= size_of && ram <= size_of + 4096,
            "RAM {ram} against size_of {size_of}"
        );
        assert!(
            flash > 10_000 && fw["sections"]["text"].as_u64().unwrap() < flash,
            "{fw}"
        );
    } else {
        eprintln!("the thumbv7em-none-eabihf target is not installed: --flash is not checked");
    }
}

/// A model file that is not the crate's: refused before anything is built, naming both.
#[test]
fn bench_refuses_a_model_that_is_not_the_crates() {
    let tmp = tempfile::tempdir().unwrap();
    let o = uavgen(&[
        "bench",
        "--crate",
        "generated/pd_hover",
        "--model",
        "models/pd_paper.json",
        "--steps",
        "1",
        "--work-dir",
        tmp.path().join("work").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("pd_paper.json") && e.contains("not generated from this model file") && e.contains("pd_hover.json"),
        "{e}"
    );
    assert!(
        !tmp.path().join("work").exists(),
        "nothing is built for a refused model"
    );
}
