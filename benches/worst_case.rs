//! Worst-case RTI benchmark of every shipped generated crate, with the generic
//! reference solver (interpreted model + clarabel) side by side:
//! `cargo bench -p uavgen-benches --bench worst_case` (add
//! `RUSTFLAGS="-C target-cpu=native"` for this machine's vector units).
//! The scenario is benches/scenario.rs; docs/benchmarks.md has the results.
#![allow(clippy::unnecessary_cast, clippy::manual_is_multiple_of)]

use std::path::PathBuf;

macro_rules! shipped {
    ($($module:ident => $krate:ident),*) => {
        $(#[allow(dead_code)] // the callgrind entry points are for `uavgen bench`
        mod $module {
            use $krate as solver;
            include!("scenario.rs");
        })*
    };
}

shipped!(sindy => sindy_m100, pd_m100_model => pd_m100, pd_paper_model => pd_paper, pd_hover_model => pd_hover, pd_hover_f32_model => pd_hover_f32);

fn arg(name: &str, default: usize) -> usize {
    let args: Vec<String> = std::env::args().collect();
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn report(name: &str, json: &str) {
    println!("{json}");
    let _ = name;
}

fn main() {
    let steps = arg("--steps", 3334);
    let generic_steps = arg("--generic-steps", 50);
    let pinned = core_affinity::get_core_ids()
        .and_then(|ids| ids.last().copied())
        .is_some_and(core_affinity::set_for_current);
    eprintln!("worst-case benchmark: {steps} RTI steps per trajectory, pinned: {pinned}");
    let _ = sindy::run(50, 99);
    report("sindy_m100", &sindy::to_json(&sindy::run(steps, 1), "sindy_m100"));
    let _ = pd_m100_model::run(50, 99);
    report(
        "pd_m100",
        &pd_m100_model::to_json(&pd_m100_model::run(steps, 1), "pd_m100"),
    );
    let _ = pd_paper_model::run(50, 99);
    report(
        "pd_paper",
        &pd_paper_model::to_json(&pd_paper_model::run(steps, 1), "pd_paper"),
    );
    let _ = pd_hover_model::run(50, 99);
    report(
        "pd_hover",
        &pd_hover_model::to_json(&pd_hover_model::run(steps, 1), "pd_hover"),
    );
    let _ = pd_hover_f32_model::run(50, 99);
    report(
        "pd_hover_f32",
        &pd_hover_f32_model::to_json(&pd_hover_f32_model::run(steps, 1), "pd_hover_f32"),
    );
    if generic_steps > 0 {
        let models = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models");
        for (name, dir) in [("sindy_m100", "sindy_m100"), ("pd_paper", "pd_paper")] {
            let model = uavgen::load(&models.join(format!("{name}.json"))).expect("shipped model");
            let dims = uavgen::bench::read_crate_dims(
                &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../generated").join(dir),
            )
            .expect("generated crate");
            let g = uavgen::bench::run_generic(
                &model,
                &dims.options,
                dims.horizon,
                dims.dt,
                dims.substeps,
                generic_steps,
                1,
            );
            println!(
                "{{\"model\": \"{name} (generic: interpreted + clarabel)\", \"steps\": {}, \"total_ns\": [{:.0}, {:.0}, {:.0}], \"failures\": {}}}",
                g.steps, g.total_ns[0], g.total_ns[1], g.total_ns[2], g.failures
            );
        }
    }
}
