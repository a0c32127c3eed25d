//! `uavgen::diagnose` on synthetic logs: the shipped SINDy model simulated (RK4, 8 substeps per
//! sample) under a random velocity-hold pilot with one catalogued effect injected at a time (its
//! own implementation here, independent of the diagnose module), plus sensor noise. The verdict
//! must name the injected effect first, a pair must be named, clean data must give `none`, and the
//! held-out one-step RMSE of the affected channels must shrink by at least half.

use std::path::Path;
use uavgen::diagnose::{diagnose, DiagnoseOptions, Diagnosis, EffectKind};
use uavgen::logs::{parse_log, FlightLog};
use uavgen::{Model, ModelIr};

const DT: f64 = 1.0 / 30.0;
const SUB: usize = 8;
const G: f64 = 9.81;
const RADIUS: f64 = 0.1651;

/// The injected effects (the truth of a synthetic log).
#[derive(Clone, Debug, Default)]
struct Truth {
    linear_drag: Option<[f64; 2]>,
    quadratic_drag: Option<[f64; 2]>,
    force_bias: Option<[f64; 3]>,
    thrust_gain: Option<f64>,
    thrust_decay: Option<f64>,
    ground_effect: Option<f64>,
    /// Delay per input, in substeps (so the truth is exact).
    latency: [usize; 4],
    lag: [Option<f64>; 4],
    stale_probability: f64,
    /// The aircraft's vertical acceleration is this × the model's vz row (a vertical loop of
    /// another stiffness): force_bias z = −κ g and thrust_gain κ = scale − 1 reproduce it exactly
    /// together, a pair that cancels at hover.
    vertical_scale: Option<f64>,
    /// Fly low (the ground effect needs it).
    low: bool,
}

/// xorshift64* with Box-Muller normals.
struct Rng(u64);
impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.uniform()
    }
    fn normal(&mut self) -> f64 {
        let (u, v) = (self.uniform().max(1e-300), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap()
}

/// The shipped sindy_m100 without its identified input delay: the synthetic plant and the base
/// model alike (every effect is added by the cases themselves).
fn model() -> (Model, String) {
    let path = repo().join("models/sindy_m100.json");
    let mut v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("corrections");
    let text = serde_json::to_string_pretty(&v).unwrap() + "\n";
    (uavgen::model::parse(&text, "sindy_m100.json").unwrap(), text)
}

/// The true derivative: extended state [x (12), lag states (4), t].
fn truth_deriv(ir: &ModelIr, tr: &Truth, z: &[f64; 17], cmd: &[f64; 4]) -> [f64; 17] {
    let x = &z[..12];
    let mut u = *cmd;
    for j in 0..4 {
        if tr.lag[j].is_some() {
            u[j] = z[12 + j];
        }
    }
    let f = ir.eval_f(x, &u);
    let mut out = [0.0; 17];
    out[..12].copy_from_slice(&f);
    let v = [x[6], x[7], x[8]];
    let thrust = [f[6], f[7], f[8] + G];
    let mut dv = [0.0; 3];
    if let Some([d, dz]) = tr.linear_drag {
        dv = [dv[0] - d * v[0], dv[1] - d * v[1], dv[2] - dz * v[2]];
    }
    if let Some([c, cz]) = tr.quadratic_drag {
        let s = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + 0.01).sqrt();
        dv = [dv[0] - c * s * v[0], dv[1] - c * s * v[1], dv[2] - cz * s * v[2]];
    }
    if let Some(b) = tr.force_bias {
        dv = [dv[0] + b[0], dv[1] + b[1], dv[2] + b[2]];
    }
    if let Some(k) = tr.thrust_gain {
        dv = [dv[0] + k * thrust[0], dv[1] + k * thrust[1], dv[2] + k * thrust[2]];
    }
    if let Some(c) = tr.thrust_decay {
        let k = c * z[16];
        dv = [dv[0] + k * thrust[0], dv[1] + k * thrust[1], dv[2] + k * thrust[2]];
    }
    if let Some(k) = tr.ground_effect {
        let q = (RADIUS / 4.0) * (RADIUS / 4.0);
        dv[2] += k * thrust[2] * q / (x[2] * x[2] + q);
    }
    if let Some(k) = tr.vertical_scale {
        dv[2] += (k - 1.0) * f[8];
    }
    for i in 0..3 {
        out[6 + i] += dv[i];
    }
    for j in 0..4 {
        if let Some(tau) = tr.lag[j] {
            out[12 + j] = (cmd[j] - z[12 + j]) / tau;
        }
    }
    out[16] = 1.0;
    out
}

fn rk4(g: impl Fn(&[f64; 17]) -> [f64; 17], z: &[f64; 17], h: f64) -> [f64; 17] {
    let add = |a: &[f64; 17], s: f64, b: &[f64; 17]| -> [f64; 17] { std::array::from_fn(|i| a[i] + s * b[i]) };
    let k1 = g(z);
    let k2 = g(&add(z, h / 2.0, &k1));
    let k3 = g(&add(z, h / 2.0, &k2));
    let k4 = g(&add(z, h, &k3));
    std::array::from_fn(|i| z[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// Fly `seconds` with the truth `tr`; the log as CSV text (sensor noise, optional sample-and-hold).
fn fly(ir: &ModelIr, tr: &Truth, seconds: f64, seed: u64) -> String {
    let mut rng = Rng(seed.wrapping_mul(0x9E3779B97F4A7C15) | 1);
    let n = (seconds / DT) as usize;
    let mut z = [0.0; 17];
    z[2] = if tr.low { 0.5 } else { 5.0 };
    let mut text = String::from(
        "# rate_hz: 30\nt,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate\n",
    );
    // Command history per substep for the delays.
    let mut history: Vec<[f64; 4]> = Vec::new();
    let (mut vsp, mut zsp, mut yaw_rate_sp, mut jitter) = ([0.0; 2], z[2], 0.0, [0.0; 4]);
    let (mut next_sp, mut next_jitter) = (0usize, 0usize);
    let mut held: Option<[f64; 12]> = None;
    for k in 0..n {
        if k >= next_sp {
            vsp = [rng.range(-3.5, 3.5), rng.range(-3.5, 3.5)];
            zsp = if tr.low {
                rng.range(0.05, 1.2)
            } else {
                rng.range(2.0, 9.0)
            };
            yaw_rate_sp = rng.range(-0.6, 0.6);
            next_sp = k + (rng.range(1.5, 4.0) / DT) as usize;
        }
        if k >= next_jitter {
            jitter = [
                rng.range(-0.6, 0.6),
                rng.range(-0.08, 0.08),
                rng.range(-0.08, 0.08),
                rng.range(-0.3, 0.3),
            ];
            next_jitter = k + rng.range(2.0, 8.0) as usize;
        }
        // The pilot (on the true state): velocity hold, altitude hold, yaw-rate steps.
        let (yaw, v) = (z[5], [z[6], z[7]]);
        let a = [0.8 * (vsp[0] - v[0]), 0.8 * (vsp[1] - v[1])];
        let pitch = (a[0] * yaw.cos() + a[1] * yaw.sin()) / G;
        let roll = (a[0] * yaw.sin() - a[1] * yaw.cos()) / G;
        let u = [
            (1.2 * (zsp - z[2]) + jitter[0]).clamp(-2.5, 2.5),
            (roll + jitter[1]).clamp(-0.35, 0.35),
            (pitch + jitter[2]).clamp(-0.35, 0.35),
            (yaw_rate_sp + jitter[3]).clamp(-1.0, 1.0),
        ];
        // Measurement: noise, then sample-and-hold.
        let sigma = [
            0.005, 0.005, 0.005, 0.001, 0.001, 0.001, 0.005, 0.005, 0.005, 0.003, 0.003, 0.003,
        ];
        let mut y: [f64; 12] = std::array::from_fn(|i| z[i] + sigma[i] * rng.normal());
        if let Some(h) = held {
            if rng.uniform() < tr.stale_probability {
                y = h;
            }
        }
        held = Some(y);
        let row: Vec<String> = std::iter::once(k as f64 * DT)
            .chain(y)
            .chain(u)
            .map(|v| format!("{v}"))
            .collect();
        text.push_str(&row.join(","));
        text.push('\n');
        for _ in 0..SUB {
            history.push(u);
            let now = history.len() - 1;
            let cmd: [f64; 4] = std::array::from_fn(|j| history[now.saturating_sub(tr.latency[j])][j]);
            z = rk4(|z| truth_deriv(ir, tr, z, &cmd), &z, DT / SUB as f64);
        }
    }
    text
}

fn logs(tr: &Truth, seed: u64) -> (FlightLog, FlightLog) {
    let (m, _) = model();
    let ir = ModelIr::new(&m);
    let train = parse_log(&fly(&ir, tr, 120.0, seed), "train.csv").unwrap();
    let test = parse_log(&fly(&ir, tr, 60.0, seed + 1000), "test.csv").unwrap();
    (train, test)
}

fn run(name: &str, tr: &Truth, seed: u64) -> Diagnosis {
    run_with(name, tr, seed, DiagnoseOptions::default().candidates)
}

/// [`run`] with only the `candidates` evaluated (`--effects`).
fn run_with(name: &str, tr: &Truth, seed: u64, candidates: Vec<EffectKind>) -> Diagnosis {
    // DIAGNOSE_SEED_OFFSET=k flies other logs (robustness checks; docs/diagnose.md).
    let offset: u64 = std::env::var("DIAGNOSE_SEED_OFFSET")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    let seed = seed + 100 * offset;
    let (m, text) = model();
    let (train, test) = logs(tr, seed);
    let t0 = std::time::Instant::now();
    let options = DiagnoseOptions {
        model_text: Some(text),
        where_analysis: false,
        candidates,
        ..DiagnoseOptions::default()
    };
    let d = diagnose(&m, &[train], &[test], &options).unwrap();
    let ranking: Vec<String> = d.rounds[0]
        .candidates
        .iter()
        .map(|c| format!("{} {:.0}{}", c.name, c.score, if c.significant { "*" } else { "" }))
        .collect();
    eprintln!(
        "{name}: verdict {:?} ({:.1} s); round 1: {}",
        d.verdict,
        t0.elapsed().as_secs_f64(),
        ranking.join(", ")
    );
    for e in d.effects.iter().filter(|e| e.selected) {
        eprintln!(
            "  {}: {} ± {}; held-out RMSE {:?} → {:?} (reduction {:.1} %)",
            e.name,
            e.parameters,
            e.uncertainty,
            e.heldout_rmse_before,
            e.heldout_rmse_after,
            100.0 * e.heldout_reduction
        );
    }
    d
}

/// Held-out one-step RMSE of the effect's channels (pooled) before and after all named effects.
fn shrink_of(d: &Diagnosis, channels: &[&str]) -> f64 {
    let (mut b, mut a) = (0.0, 0.0);
    for s in d
        .shrink
        .per_state
        .iter()
        .filter(|s| channels.contains(&s.state.as_str()))
    {
        b += s.one_step_rmse_before.unwrap().powi(2);
        a += s.one_step_rmse_after.unwrap().powi(2);
    }
    1.0 - (a / b).sqrt()
}

fn check_top(name: &str, tr: Truth, seed: u64, channels: &[&str]) -> Diagnosis {
    let d = run(name, &tr, seed);
    assert_eq!(d.verdict.first().map(String::as_str), Some(name), "{:?}", d.verdict);
    let s = shrink_of(&d, channels);
    eprintln!("  shrink of {channels:?}: {:.1} %", 100.0 * s);
    assert!(
        s >= 0.5,
        "{name}: held-out RMSE of {channels:?} shrank by {:.1} %",
        100.0 * s
    );
    d
}

const VEL: [&str; 3] = ["vx", "vy", "vz"];

#[test]
fn clean_data_gives_none() {
    let d = run("clean", &Truth::default(), 1);
    assert_eq!(d.verdict, vec!["none".to_string()]);
    assert!(d.corrections.linear_drag.is_none() && d.corrections.latency.is_empty());
}

#[test]
fn linear_drag() {
    let tr = Truth {
        linear_drag: Some([0.3, 0.4]),
        ..Truth::default()
    };
    check_top("linear_drag", tr, 2, &VEL);
}

#[test]
fn quadratic_drag() {
    let tr = Truth {
        quadratic_drag: Some([0.1, 0.15]),
        ..Truth::default()
    };
    check_top("quadratic_drag", tr, 3, &VEL);
}

#[test]
fn force_bias() {
    let tr = Truth {
        force_bias: Some([0.4, -0.3, 0.3]),
        ..Truth::default()
    };
    check_top("force_bias", tr, 4, &VEL);
}

#[test]
fn thrust_gain() {
    let tr = Truth {
        thrust_gain: Some(-0.12),
        ..Truth::default()
    };
    check_top("thrust_gain", tr, 5, &VEL);
}

#[test]
fn thrust_decay() {
    let tr = Truth {
        thrust_decay: Some(-0.0015),
        ..Truth::default()
    };
    check_top("thrust_decay", tr, 6, &VEL);
}

#[test]
fn ground_effect() {
    let tr = Truth {
        ground_effect: Some(1.5),
        low: true,
        ..Truth::default()
    };
    check_top("ground_effect", tr, 7, &["vz"]);
}

#[test]
fn latency() {
    let tr = Truth {
        latency: [0, 3 * SUB, 3 * SUB, 0],
        ..Truth::default()
    };
    let d = check_top("latency", tr, 8, &["roll_rate", "pitch_rate"]);
    // A pure delay is `latency`, not `channel_response`, and within 20 % of the truth (issue 27).
    assert!(!d.verdict.iter().any(|v| v == "channel_response"), "{:?}", d.verdict);
    for input in ["u_roll", "u_pitch"] {
        let v = d.corrections.latency.get(input).copied().unwrap_or(0.0);
        assert!((v - 0.1).abs() <= 0.02, "{input}: fitted {v} s against 0.1 s");
    }
}

/// The aircraft's vertical acceleration is 0.55 × the model's (a softer vertical loop) and it meets
/// a steady updraft of 1 m/s². Among the linear effects (`--effects linear_drag,force_bias,
/// thrust_gain`), force_bias explains the updraft alone; with thrust_gain added the pair
/// reproduces the softer loop exactly — κ = −0.45 with the bias moved to ≈ +5.4 m/s², two forces
/// that cancel at hover (the nano of issue 27: +8.3 m/s² and −0.85). The pair is not named, the
/// named bias stays within its plausible range, and the report says why.
#[test]
fn a_cancelling_pair_is_not_named() {
    let tr = Truth {
        vertical_scale: Some(0.55),
        force_bias: Some([0.0, 0.0, 1.0]),
        ..Truth::default()
    };
    let linear = vec![EffectKind::LinearDrag, EffectKind::ForceBias, EffectKind::ThrustGain];
    let d = run_with("cancelling pair", &tr, 19, linear);
    for w in &d.warnings {
        eprintln!("  warning: {w}");
    }
    let named = |n: &str| d.verdict.iter().any(|v| v == n);
    assert!(named("force_bias"), "{:?}", d.verdict);
    assert!(!named("thrust_gain"), "{:?}", d.verdict);
    let b = d.corrections.force_bias.unwrap();
    assert!(b[0].hypot(b[1]) <= 0.3 * G && b[2].abs() <= 0.3 * G, "{b:?}");
    assert!(
        d.warnings
            .iter()
            .any(|w| w.contains("thrust_gain not named") && w.contains("not identifiable")),
        "{:?}",
        d.warnings
    );
}

#[test]
fn actuator_lag() {
    let tr = Truth {
        lag: [None, Some(0.12), Some(0.12), None],
        ..Truth::default()
    };
    check_top("actuator_lag", tr, 9, &["roll_rate", "pitch_rate"]);
}

#[test]
fn stale_samples() {
    let tr = Truth {
        stale_probability: 0.3,
        ..Truth::default()
    };
    // The stale policy (interpolate, the default) applies before any effect, so the shrink
    // figures are both on interpolated data; what treating the rows as missing buys is the
    // stale_samples round's own held-out reduction (raw → interpolated).
    let d = run("stale_samples", &tr, 10);
    assert_eq!(
        d.verdict.first().map(String::as_str),
        Some("stale_samples"),
        "{:?}",
        d.verdict
    );
    let e = d.effects.iter().find(|e| e.name == "stale_samples").unwrap();
    assert!(e.heldout_reduction >= 0.5, "reduction {:.3}", e.heldout_reduction);
    let (b, a) = (
        d.shrink.before.horizon.as_ref().unwrap().overall_rmse,
        d.shrink.after.horizon.as_ref().unwrap().overall_rmse,
    );
    assert_eq!(a, b, "no model effect: the same model on the same data");
}

#[test]
fn a_pair_is_named() {
    let tr = Truth {
        linear_drag: Some([0.3, 0.4]),
        latency: [2 * SUB, 0, 0, 2 * SUB],
        ..Truth::default()
    };
    let d = run("pair", &tr, 11);
    let mut v = d.verdict.clone();
    v.sort();
    assert_eq!(v, vec!["latency".to_string(), "linear_drag".to_string()]);
}

/// `diagnose --plant`'s closed-loop verdict in the report: a corrected model that flies worse than
/// the base (issue 13: the circle 5.18 → 7.16 m on m100_like) is flagged as not recommended for
/// closed loop in report.md and report.json; one that flies better is not.
#[test]
fn a_corrected_model_that_flies_worse_is_not_presented_as_the_fix() {
    use uavgen::diagnose::{ClosedLoop, ClosedLoopRun};
    use uavgen::track::Verdict;
    let mut d = run("clean", &Truth::default(), 1);
    let flight = |name: &str, before: (f64, Verdict), after: (f64, Verdict)| ClosedLoopRun {
        trajectory: name.into(),
        seconds: 30.0,
        rmse_before: before.0,
        rmse_after: after.0,
        mae_before: 0.0,
        mae_after: 0.0,
        d1_before: 1.0,
        d1_after: 1.0,
        out_of_bounds_before: 0,
        out_of_bounds_after: 0,
        verdict_before: before.1,
        verdict_after: after.1,
    };
    for (runs, worse) in [
        (
            vec![
                flight("sinusoid", (0.25, Verdict::Tracked), (0.25, Verdict::Tracked)),
                flight("circle", (5.18, Verdict::DidNotTrack), (7.16, Verdict::DidNotTrack)),
            ],
            true,
        ),
        (
            vec![flight("circle", (5.18, Verdict::DidNotTrack), (0.25, Verdict::Tracked))],
            false,
        ),
    ] {
        let (verdict, note) = uavgen::track::compare::judge(&runs, "plants/m100_like.json");
        d.shrink.closed_loop = ClosedLoop {
            status: "measured".into(),
            plant: Some("plants/m100_like.json".into()),
            note,
            verdict: Some(verdict),
            runs,
        };
        let md = d.report_markdown(&[]);
        let json: serde_json::Value = serde_json::from_str(&d.report_json()).unwrap();
        let cl = &json["shrink"]["closed_loop"];
        assert_eq!(cl["verdict"], if worse { "worse" } else { "better" });
        assert_eq!(
            md.contains("not recommended for closed loop"),
            worse,
            "{}",
            &md[..md.len().min(800)]
        );
        assert_eq!(cl["note"].as_str().unwrap().starts_with("NOT RECOMMENDED"), worse);
        if worse {
            assert!(md.contains("circle RMSE 5.180 → 7.160 m"), "{md}");
            assert_eq!(cl["runs"][1]["verdict_after"], "did not track");
        }
    }
}

/// The aircraft's roll and pitch loops are slower than the model's (their own part × 0.45) and
/// have none of its couplings: the truth is the model file with a `loop_mismatch` block, flown by
/// its own IR. The verdict names `loop_mismatch` first, with the gains within 0.1 and the
/// couplings within 0.25 of the truth, and the step response of the corrected model's roll is
/// slower than the base model's.
#[test]
fn loop_mismatch() {
    use uavgen::model::corrections::LoopMismatch;
    let (m, text) = model();
    let mut c = uavgen::model::Corrections::default();
    for loop_ in ["roll_rate", "pitch_rate"] {
        c.loop_mismatch.insert(
            loop_.to_string(),
            LoopMismatch {
                gain: 0.45,
                coupling: 0.0,
            },
        );
    }
    let truth_text = uavgen::model::attach_corrections(&text, "truth.json", &c).unwrap();
    let truth = uavgen::model::parse(&truth_text, "truth.json").unwrap();
    let ir = ModelIr::new(&truth);
    let tr = Truth::default();
    let train = parse_log(&fly(&ir, &tr, 120.0, 41), "train.csv").unwrap();
    let test = parse_log(&fly(&ir, &tr, 60.0, 1041), "test.csv").unwrap();
    let options = DiagnoseOptions {
        model_text: Some(text),
        where_analysis: false,
        ..DiagnoseOptions::default()
    };
    let d = diagnose(&m, &[train], &[test], &options).unwrap();
    eprintln!("verdict {:?}; corrections {:?}", d.verdict, d.corrections);
    assert_eq!(
        d.verdict.first().map(String::as_str),
        Some("loop_mismatch"),
        "{:?}",
        d.verdict
    );
    for loop_ in ["roll_rate", "pitch_rate"] {
        let fitted = d.corrections.loop_mismatch.get(loop_).expect("the loop is named");
        assert!((fitted.gain - 0.45).abs() < 0.1, "{loop_}: gain {}", fitted.gain);
    }
    // Both rows of sindy_m100 have coupling terms (roll: u_roll·sin(ψ), sin(roll)·sin(ψ); pitch:
    // roll·u_yaw_rate), absent from the truth: both couplings are fitted near 0. (A row without
    // coupling terms keeps coupling 1, unfitted: loop_fit.rs.)
    for loop_ in ["roll_rate", "pitch_rate"] {
        let coupling = d.corrections.loop_mismatch[loop_].coupling;
        assert!(coupling.abs() < 0.25, "{loop_}: coupling {coupling}");
    }
    let roll = d.response_times.iter().find(|t| t.input == "u_roll").unwrap();
    assert!(roll.corrected.t63.unwrap() > roll.base.t63.unwrap(), "{roll:?}");
    assert!(
        d.shrink.after.horizon.as_ref().unwrap().overall_rmse < d.shrink.before.horizon.as_ref().unwrap().overall_rmse
    );
}
