//! The diagnosis self-check on a reduced set of cases (`uavgen diagnose --self-check` runs them all):
//! every plant effect at realistic magnitude, one pair, fresh nominal logs.

use std::path::PathBuf;
use uavgen::selfcheck::{self, cases::reduced_cases, SelfCheckOptions};

#[test]
fn diagnose_names_withheld_effects() {
    let plants = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../plants");
    let options = SelfCheckOptions {
        cases: reduced_cases(),
        ..SelfCheckOptions::default()
    };
    let start = std::time::Instant::now();
    let check = selfcheck::run(&plants, &options, &mut |done, total, case| {
        eprintln!("[{done}/{total}] {case} ({:.0} s)", start.elapsed().as_secs_f64())
    })
    .unwrap();
    eprintln!("{}", check.markdown());
    // Named correctly but with a held-out shrink below 50 % (docs/diagnosis.md says why): asserted
    // as such, so that a change in either direction shows up here.
    const KNOWN_SHORTFALLS: [&str; 1] = ["motor_lag (realistic)"];
    for r in &check.results {
        if r.truth.len() == 1 && r.truth[0] != "none" {
            assert!(
                r.top1_correct,
                "{}: verdict {:?}, must name {:?}",
                r.case, r.verdict, r.truth
            );
        }
        if KNOWN_SHORTFALLS.contains(&r.case.as_str()) {
            assert!(
                r.top1_correct && !r.shrink_ok(),
                "{}: now passes the shrink; update docs/diagnosis.md",
                r.case
            );
        } else {
            assert!(
                r.passes(),
                "{}: verdict {:?}, must name {:?}, shrink {:?} / effect gap {:?}",
                r.case,
                r.verdict,
                r.truth,
                r.shrink,
                r.effect_gap_shrink
            );
        }
    }
}
