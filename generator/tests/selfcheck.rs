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
    for r in &check.results {
        if r.truth.len() == 1 && r.truth[0] != "none" {
            assert!(
                r.top1_correct,
                "{}: verdict {:?}, must name {:?}",
                r.case, r.verdict, r.truth
            );
        }
        assert!(
            r.passes(),
            "{}: verdict {:?}, must name {:?}, shrink {:?} / effect gap {:?}",
            r.case,
            r.verdict,
            r.truth,
            r.shrink,
            r.effect_gap_shrink
        );
        // A named true effect's figures are measured and finite.
        for (name, g) in &r.effect_gap_shrink {
            assert!(
                g.is_some_and(f64::is_finite),
                "{}: {name}: no effect-gap figure",
                r.case
            );
        }
    }
    assert!(check.passed());
}
