//! The PD fit (`uavgen::identify::pd`): recovery of known ξ from synthetic data, scale fixing,
//! bounds and errors, and the fit on the M100 logs when `../shared` is present.

mod shared;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;
use uavgen::discretize::discrete_step;
use uavgen::identify::dataset::{build, Dataset, DatasetOptions, SegmentData};
use uavgen::identify::pd::{fit, PdFitError, PdFitOptions, PdScale, PdWeighting, ROW_NAMES};
use uavgen::model::parse;
use uavgen::ModelIr;

/// models/pd_hover.json's ξ.
const HOVER_XI: [f64; 16] = [
    4.8, 3.2, 3.2, 0.27, 3.2, 3.2, 4.8, 0.64, 0.64, 0.27, 0.0, 0.0, 23.544, 0.05, 0.05, 0.09,
];
/// A model with every ξ away from its bounds (acceleration feedback, unequal inertias).
const RICH_XI: [f64; 16] = [
    5.1, 2.9, 3.7, 0.33, 2.6, 3.9, 4.2, 0.51, 0.77, 0.36, 0.4, 0.03, 23.544, 0.06, 0.07, 0.12,
];
const MASS: f64 = 2.4;
const GRAVITY: f64 = 9.81;

fn model_text(xi: &[f64; 16]) -> String {
    serde_json::json!({
        "format": "uavgen-model/1", "kind": "pd", "name": "truth",
        "mass": MASS, "gravity": GRAVITY, "xi": xi.to_vec(),
    })
    .to_string()
}

/// Simulate the model under random piecewise-constant inputs; ẋ exactly from the model, plus
/// optional Gaussian noise of relative size `noise` (of each derivative's RMS) on ẋ.
fn synthetic(xi: &[f64; 16], seed: u64, segments: usize, samples: usize, noise: f64) -> Dataset {
    let model = parse(&model_text(xi), "truth").unwrap();
    let ir = ModelIr::new(&model);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let dt = 1.0 / 30.0;
    let mut out = Vec::new();
    for s in 0..segments {
        let mut x = vec![0.0; 12];
        x[2] = 5.0;
        x[5] = rng.gen_range(-3.0..3.0);
        let mut u = [0.0; 4];
        let mut hold = 0;
        let mut seg = SegmentData {
            log: 0,
            segment: s,
            dt,
            ..Default::default()
        };
        for k in 0..samples {
            if hold == 0 {
                u = [
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-0.3..0.3),
                    rng.gen_range(-0.3..0.3),
                    rng.gen_range(-1.0..1.0),
                ];
                hold = rng.gen_range(5..40);
            }
            hold -= 1;
            let f = ir.eval_f(&x, &u);
            seg.t.push(k as f64 * dt);
            seg.x.push(x.clone().try_into().unwrap());
            seg.u.push(u);
            seg.dx.push(f.try_into().unwrap());
            x = discrete_step(&ir, &x, &u, dt, 4);
        }
        out.push(seg);
    }
    if noise > 0.0 {
        let mut rms = [0.0; 12];
        let n: usize = out.iter().map(|s| s.dx.len()).sum();
        for s in &out {
            for d in &s.dx {
                for i in 0..12 {
                    rms[i] += d[i] * d[i] / n as f64;
                }
            }
        }
        for s in &mut out {
            for d in &mut s.dx {
                for i in 0..12 {
                    // Box-Muller
                    let (a, b): (f64, f64) = (rng.gen_range(1e-12..1.0), rng.gen_range(0.0..1.0));
                    let z = (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos();
                    d[i] += noise * rms[i].sqrt() * z;
                }
            }
        }
    }
    Dataset { segments: out }
}

/// Every ξ fitted (no acceleration feedback held at 0), with the given scale.
fn options(scale: PdScale) -> PdFitOptions {
    PdFitOptions {
        scale,
        fixed: vec![],
        ..PdFitOptions::default()
    }
}

fn assert_close(fitted: &[f64; 16], truth: &[f64; 16], rel: f64, abs: f64, what: &str) {
    for k in 0..16 {
        let err = (fitted[k] - truth[k]).abs();
        assert!(
            err <= rel * truth[k].abs() + abs,
            "{what}: ξ{} = {} vs {} (error {err:.3e})\nfitted {fitted:?}",
            k + 1,
            fitted[k],
            truth[k]
        );
    }
}

#[test]
fn noise_free_recovers_pd_hover() {
    let data = synthetic(&HOVER_XI, 1, 3, 600, 0.0);
    // ξ11 = ξ12 = 0 are held by default; fitted too, they come out 0 (ξ12 on its bound).
    let all = options(PdScale::Inertia([0.05, 0.05, 0.09]));
    for weighting in [PdWeighting::Acceleration, PdWeighting::Force] {
        let f = fit(
            &data,
            &PdFitOptions {
                weighting,
                ..all.clone()
            },
            "fit",
            serde_json::Value::Null,
        )
        .unwrap();
        assert_close(
            &f.xi,
            &HOVER_XI,
            1e-6,
            1e-8,
            &format!("pd_hover, all ξ fitted, {weighting:?}"),
        );
    }
    let f = fit(&data, &PdFitOptions::default(), "fit", serde_json::json!("synthetic")).unwrap();
    assert_close(&f.xi, &HOVER_XI, 1e-6, 1e-8, "pd_hover");
    assert_eq!((f.xi[10], f.xi[11]), (0.0, 0.0));
    let d = &f.diagnostics;
    assert!((d.hover_ratio - 1.0).abs() < 1e-6);
    assert!(d.stable, "{}", d.summary());
    assert!(d.free_runs_bounded(), "{}", d.summary());
    for r in &d.rows {
        assert!(r.residual_rms < 1e-8 * (1.0 + r.inertial_rms), "{}", d.summary());
    }
    assert!(d.translation.converged && d.rotation.converged);
}

#[test]
fn noise_free_recovers_interior_parameters_with_known_inertia() {
    let data = synthetic(&RICH_XI, 2, 3, 600, 0.0);
    let f = fit(
        &data,
        &options(PdScale::Inertia([0.06, 0.07, 0.12])),
        "fit",
        serde_json::Value::Null,
    )
    .unwrap();
    assert_close(&f.xi, &RICH_XI, 1e-6, 1e-9, "rich, known inertia");
    assert!(f.diagnostics.translation.at_bounds.is_empty() && f.diagnostics.rotation.at_bounds.is_empty());
}

#[test]
fn noise_free_recovers_inertias_with_one_gain_fixed() {
    let data = synthetic(&RICH_XI, 3, 3, 600, 0.0);
    for xi in [2, 3, 8] {
        let f = fit(
            &data,
            &options(PdScale::Gain {
                xi,
                value: RICH_XI[xi - 1],
            }),
            "fit",
            serde_json::Value::Null,
        )
        .unwrap();
        eprintln!(
            "gain ξ{xi} fixed: rotation condition {:.3e}",
            f.diagnostics.rotation.condition
        );
        assert_close(&f.xi, &RICH_XI, 1e-6, 1e-9, &format!("ξ{xi} fixed"));
    }
}

/// The rotational rows are homogeneous: doubling the known inertias doubles every rotational ξ and
/// leaves the translational ones alone.
#[test]
fn rotational_scale_follows_the_fixed_inertia() {
    let data = synthetic(&RICH_XI, 4, 2, 500, 0.0);
    let f = fit(
        &data,
        &options(PdScale::Inertia([0.12, 0.14, 0.24])),
        "fit",
        serde_json::Value::Null,
    )
    .unwrap();
    let mut expect = RICH_XI;
    for k in [2, 3, 4, 5, 6, 8, 9, 10, 12, 14, 15, 16] {
        expect[k - 1] *= 2.0;
    }
    assert_close(&f.xi, &expect, 1e-6, 1e-9, "doubled inertia");
    // Fixing a gain at 1 (the paper's normalisation) divides the rotational ξ by that gain.
    let f = fit(
        &data,
        &options(PdScale::Gain { xi: 2, value: 1.0 }),
        "fit",
        serde_json::Value::Null,
    )
    .unwrap();
    let mut expect = RICH_XI;
    for k in [2, 3, 4, 5, 6, 8, 9, 10, 12, 14, 15, 16] {
        expect[k - 1] /= RICH_XI[1];
    }
    assert_close(&f.xi, &expect, 1e-6, 1e-9, "ξ2 = 1");
}

/// `synthetic`'s data in the integral form (what `identify` fits by default): sample k stands
/// for [t_k, t_{k+1}], its target is the mean slope, `x_next` the interval's end.
fn interval_form(data: Dataset) -> Dataset {
    let segments = data
        .segments
        .into_iter()
        .map(|s| {
            let n = s.x.len() - 1;
            let dx = (0..n)
                .map(|k| std::array::from_fn(|i| (s.x[k + 1][i] - s.x[k][i]) / s.dt))
                .collect();
            SegmentData {
                t: s.t[..n].to_vec(),
                x_next: s.x[1..].to_vec(),
                x: s.x[..n].to_vec(),
                u: s.u[..n].to_vec(),
                dx,
                ..s
            }
        })
        .collect();
    Dataset { segments }
}

/// The integral form (mean slope against the model at the interval's midpoint) recovers ξ to the
/// midpoint rule's error, O((sΔt)²/24): within 2 % on noise-free data, with no derivative at all.
#[test]
fn integral_form_recovers_the_parameters() {
    let data = interval_form(synthetic(&RICH_XI, 2, 3, 600, 0.0));
    assert!(data.is_interval_form());
    let f = fit(
        &data,
        &options(PdScale::Inertia([0.06, 0.07, 0.12])),
        "fit",
        serde_json::Value::Null,
    )
    .unwrap();
    eprintln!("integral form: {:?}", f.xi);
    assert_close(&f.xi, &RICH_XI, 0.02, 0.005, "integral form, known inertia");
    let data = interval_form(synthetic(&HOVER_XI, 1, 3, 600, 0.0));
    let f = fit(&data, &PdFitOptions::default(), "fit", serde_json::Value::Null).unwrap();
    assert!(
        (f.diagnostics.hover_ratio - 1.0).abs() < 0.01,
        "{}",
        f.diagnostics.hover_ratio
    );
}

#[test]
fn small_noise_gives_a_few_percent() {
    let data = synthetic(&RICH_XI, 5, 4, 900, 0.01);
    let f = fit(
        &data,
        &options(PdScale::Inertia([0.06, 0.07, 0.12])),
        "fit",
        serde_json::Value::Null,
    )
    .unwrap();
    eprintln!("fitted with 1% noise on ẋ: {:?}\n{}", f.xi, f.diagnostics.summary());
    // ξ11 and ξ12 multiply the measured accelerations (errors in variables): absolute tolerance.
    assert_close(&f.xi, &RICH_XI, 0.03, 0.0, "1% noise (gains)");
    let data = synthetic(&HOVER_XI, 6, 4, 900, 0.01);
    let f = fit(&data, &PdFitOptions::default(), "fit", serde_json::Value::Null).unwrap();
    assert_close(&f.xi, &HOVER_XI, 0.03, 0.01, "1% noise, pd_hover");
    assert!((f.diagnostics.hover_ratio - 1.0).abs() < 0.01);
    assert!(f.diagnostics.stable && f.diagnostics.free_runs_bounded());
}

#[test]
fn fitted_file_loads_and_round_trips() {
    let data = synthetic(&HOVER_XI, 7, 2, 400, 0.0);
    let f = fit(
        &data,
        &PdFitOptions::default(),
        "pd_fit_test",
        serde_json::json!({ "logs": ["synthetic"] }),
    )
    .unwrap();
    let text = f.to_json();
    let model = parse(&text, "pd_fit_test.json").unwrap();
    assert_eq!(model.name, "pd_fit_test");
    match &model.dynamics {
        uavgen::model::Dynamics::Pd(p) => {
            assert_eq!(p.xi, f.xi);
            assert_eq!(p.mass, MASS);
        }
        _ => panic!("not a PD model"),
    }
    let prov = &model.provenance;
    assert_eq!(prov["data"]["logs"][0], "synthetic");
    assert!(prov["condition"]["rotation"].as_f64().unwrap() >= 1.0);
    assert!(prov["residual_rms"]["yaw"].is_number());
    assert_eq!(prov["options"]["scale"]["inertia"][2], 0.09);
}

/// Bounds hold even when the data pulls a parameter outside them.
#[test]
fn bounds_are_enforced() {
    let mut xi = HOVER_XI;
    xi[9] = 0.27; // ξ10
    let mut data = synthetic(&xi, 8, 2, 400, 0.0);
    // Flip the sign of every yaw-rate input: the yaw gain ξ4 now fits negative, so it sits on 0.
    for s in &mut data.segments {
        for u in &mut s.u {
            u[3] = -u[3];
        }
    }
    let f = fit(&data, &PdFitOptions::default(), "fit", serde_json::Value::Null).unwrap();
    assert_eq!(f.xi[3], 0.0);
    assert!(
        f.diagnostics.rotation.at_bounds.contains(&4),
        "{}",
        f.diagnostics.summary()
    );
    assert!(f.xi.iter().enumerate().all(|(k, v)| k == 10 || *v >= 0.0));
    // Force ξ11 against its bound: a mass far below the truth makes the z rows want |ξ11| ≥ m.
    let f = fit(
        &synthetic(&RICH_XI, 9, 2, 400, 0.0),
        &PdFitOptions {
            mass: 0.3,
            ..options(PdScale::Inertia([0.06, 0.07, 0.12]))
        },
        "fit",
        serde_json::Value::Null,
    )
    .unwrap();
    assert!(f.xi[10].abs() <= 0.95 * 0.3 + 1e-12);
    parse(&f.to_json(), "x").unwrap();
}

#[test]
fn errors() {
    let data = synthetic(&HOVER_XI, 10, 1, 200, 0.0);
    let bad = |o: PdFitOptions| fit(&data, &o, "f", serde_json::Value::Null).unwrap_err();
    assert!(matches!(
        bad(PdFitOptions {
            mass: 0.0,
            ..Default::default()
        }),
        PdFitError::Option(_)
    ));
    assert!(matches!(
        bad(options(PdScale::Gain { xi: 13, value: 1.0 })),
        PdFitError::Option(_)
    ));
    assert!(matches!(
        bad(options(PdScale::Inertia([0.05, -1.0, 0.1]))),
        PdFitError::Option(_)
    ));
    let e = bad(PdFitOptions {
        rows: [true, true, true, false, true, true],
        ..Default::default()
    });
    match &e {
        PdFitError::Unidentifiable { xi } => assert_eq!(xi, &vec![2, 5, 8]),
        other => panic!("{other}"),
    }
    assert!(e.to_string().contains("ξ2, ξ5, ξ8"), "{e}");
    assert!(matches!(
        fit(
            &Dataset::default(),
            &PdFitOptions::default(),
            "f",
            serde_json::Value::Null
        ),
        Err(PdFitError::Empty)
    ));
    let mut nan = data.clone();
    nan.segments[0].dx[17][9] = f64::NAN;
    assert!(matches!(
        fit(&nan, &PdFitOptions::default(), "f", serde_json::Value::Null),
        Err(PdFitError::NonFinite { sample: 17, .. })
    ));
}

/// The paper's λ = 1 rad/s low-pass on everything: the equations hold only approximately for the
/// filtered signals (they are nonlinear), so the fit is close, not exact.
#[test]
fn lowpass_option_runs_and_stays_close() {
    let data = synthetic(&HOVER_XI, 11, 3, 900, 0.0);
    let f = fit(&data, &PdFitOptions::paper(), "fit", serde_json::Value::Null).unwrap();
    eprintln!("low-passed fit: {:?}", f.xi);
    assert!(
        (f.diagnostics.hover_ratio - 1.0).abs() < 0.02,
        "{}",
        f.diagnostics.summary()
    );
    assert_eq!(f.model.provenance["options"]["lowpass"]["lambda"], 1.0);
}

#[test]
fn m100_runs_1_to_5() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/flights/m100");
    if !dir.is_dir() {
        shared::skip(&dir);
        return;
    }
    let logs: Vec<_> = (1..=5)
        .map(|k| uavgen::logs::read_log(&dir.join(format!("m100_run{k}.csv"))).unwrap())
        .collect();
    let data = build(&logs, &DatasetOptions::default()).unwrap();
    for (label, o) in [
        ("default", PdFitOptions::default()),
        ("paper low-pass", PdFitOptions::paper()),
    ] {
        let f = fit(&data, &o, "pd_m100", serde_json::json!({ "logs": "m100_run1..5" })).unwrap();
        let d = &f.diagnostics;
        eprintln!("M100 runs 1-5, {label}:");
        for (k, v) in f.xi.iter().enumerate() {
            eprintln!("  ξ{:<2} = {v:.6}", k + 1);
        }
        eprintln!("{}", d.summary());
        assert_eq!(d.rows.iter().map(|r| r.row).collect::<Vec<_>>(), ROW_NAMES);
        parse(&f.to_json(), "pd_m100.json").unwrap();
        assert!(
            (d.hover_ratio - 1.0).abs() < 0.1,
            "{label}: hover ratio {}",
            d.hover_ratio
        );
        assert!(d.stable, "{label}: {}", d.summary());
        assert!(d.free_runs_bounded(), "{label}: {}", d.summary());
    }
}
