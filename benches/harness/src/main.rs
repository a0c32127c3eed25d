//! Worst-case benchmark harness for one generated crate, named `solver` in
//! Cargo.toml. `uavgen bench --crate DIR` copies this file and
//! `benches/scenario.rs` into a scratch crate pointing `solver` at DIR.
//!
//! `harness [--steps N] [--seed S] [--name NAME]` prints one JSON object with
//! the timings of N RTI steps on each of the paper's 3 trajectories (pinned to
//! the last CPU core when possible); `harness --callgrind N` runs N steps of each trajectory
//! through `measured_step` for instruction counting under callgrind;
//! `harness --callgrind-adversarial N` runs the adversarial search's N trials
//! (`scenario::run_adversarial`) the same way.

// `Real` may be f32 or f64, so `as f64` casts are needed in general; `is_multiple_of`
// is newer than the workspace's minimum Rust.
#![allow(clippy::unnecessary_cast, clippy::manual_is_multiple_of)]

mod scenario {
    include!("../../scenario.rs");
}

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter()
        .position(|a| a == name)
        .and_then(|i| args.get(i + 1))
        .cloned()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let number = |name: &str, default: u64| -> u64 {
        match arg(&args, name) {
            None => default,
            Some(v) => v.parse().unwrap_or_else(|_| {
                eprintln!("error: {name} expects a non-negative integer, got '{v}'");
                std::process::exit(2)
            }),
        }
    };
    let seed = number("--seed", 1);
    if let Some(n) = arg(&args, "--callgrind-adversarial") {
        let (s, it) = scenario::run_adversarial(n.parse().unwrap_or(100), seed);
        println!(
            "{{\"statuses\": {{\"solved\": {}, \"iteration_cap\": {}, \"hessian_regularised\": {}, \"invalid_input\": {}, \"numerical_failure\": {}, \"out_of_envelope\": {}}}, \"max_qp_iterations\": {it}}}",
            s[0], s[1], s[2], s[3], s[4], s[5]
        );
        return;
    }
    if let Some(n) = arg(&args, "--callgrind") {
        let steps = n.parse().unwrap_or(300);
        scenario::run_for_instruction_count(steps, seed);
        return;
    }
    let steps = number("--steps", 3334) as usize;
    let name = arg(&args, "--name").unwrap_or_else(|| "solver".into());
    let pinned = core_affinity::get_core_ids()
        .and_then(|ids| ids.last().copied())
        .is_some_and(core_affinity::set_for_current);
    // Warm caches and branch predictors on a different seed first.
    let _ = scenario::run(50, seed.wrapping_add(1000));
    let record = scenario::run(steps, seed);
    let json = scenario::to_json(&record, &name);
    println!("{}, \"pinned\": {pinned}}}", &json[..json.len() - 1]);
}
