//! Preprocessing (Savitzky-Golay, the paper's low-pass) and identification metrics
//! (RMSE, MAE, Willmott's d₁). The Savitzky-Golay filter is cross-checked against scipy via
//! the fixture written by `scripts/savgol_fixture.py`.

use proptest::prelude::*;
use serde::Deserialize;
use std::path::PathBuf;
use uavgen::identify::preprocess::{columnwise, try_columnwise, LowPass, PreprocessError, SavGol, PAPER_LAMBDA};
use uavgen::metrics::{self, compare, overall, MetricsError, Series};

// ---------------------------------------------------------------------------------------------
// Savitzky-Golay vs scipy

#[derive(Deserialize)]
struct Fixture {
    scipy: String,
    mode: String,
    dt: f64,
    signal: Vec<f64>,
    cases: Vec<Case>,
}

#[derive(Deserialize)]
struct Case {
    window: usize,
    order: usize,
    deriv: usize,
    coefficients: Vec<f64>,
    output: Vec<f64>,
}

fn fixture() -> Fixture {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("src/identify/preprocess/testdata/savgol_scipy.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap()
}

#[test]
fn savgol_matches_scipy_savgol_filter_interp() {
    let fx = fixture();
    assert_eq!(fx.mode, "interp");
    assert!(fx.cases.len() >= 6);
    let mut worst = 0.0f64;
    for case in &fx.cases {
        let sg = SavGol::new(case.window, case.order).unwrap();
        let label = format!(
            "window {} order {} deriv {} (scipy {})",
            case.window, case.order, case.deriv, fx.scipy
        );

        let coefficients = sg.coefficients(case.deriv, fx.dt);
        assert_eq!(coefficients.len(), case.coefficients.len(), "{label}");
        for (j, (c, e)) in coefficients.iter().zip(&case.coefficients).enumerate() {
            assert!((c - e).abs() <= 1e-10, "{label}: coefficient {j}: {c} vs scipy {e}");
        }

        let out = match case.deriv {
            0 => sg.smooth(&fx.signal),
            1 => sg.derivative(&fx.signal, fx.dt),
            d => sg.filter(&fx.signal, d, fx.dt).unwrap(),
        };
        assert_eq!(out.len(), case.output.len(), "{label}");
        for (i, (v, e)) in out.iter().zip(&case.output).enumerate() {
            assert!(
                (v - e).abs() <= 1e-10,
                "{label}: sample {i}: {v} vs scipy {e} (diff {:e})",
                v - e
            );
            worst = worst.max((v - e).abs());
        }
    }
    eprintln!("largest difference from scipy: {worst:e}");
}

/// p(t) = 0.3 − 1.2 t + 0.7 t² − 0.25 t³ (+ 0.04 t⁴ for order ≥ 4) and its derivative.
fn poly(t: f64, degree: usize) -> (f64, f64) {
    let c = [0.3, -1.2, 0.7, -0.25, 0.04];
    let (mut v, mut d) = (0.0, 0.0);
    for (m, cm) in c.iter().enumerate().take(degree + 1) {
        v += cm * t.powi(m as i32);
        if m > 0 {
            d += m as f64 * cm * t.powi(m as i32 - 1);
        }
    }
    (v, d)
}

#[test]
fn savgol_reproduces_polynomials_of_degree_up_to_order_including_edges() {
    let dt = 0.1;
    for (window, order) in [(3, 1), (5, 2), (5, 3), (7, 2), (9, 4), (11, 3)] {
        let sg = SavGol::new(window, order).unwrap();
        for degree in 0..=order.min(4) {
            let t: Vec<f64> = (0..40).map(|k| k as f64 * dt - 1.5).collect();
            let y: Vec<f64> = t.iter().map(|&t| poly(t, degree).0).collect();
            let smooth = sg.smooth(&y);
            let deriv = sg.derivative(&y, dt);
            for (i, &ti) in t.iter().enumerate() {
                let (v, d) = poly(ti, degree);
                assert!(
                    (smooth[i] - v).abs() < 1e-12,
                    "({window},{order}) degree {degree} sample {i}: {}",
                    smooth[i]
                );
                assert!(
                    (deriv[i] - d).abs() < 1e-10,
                    "({window},{order}) degree {degree} sample {i}: {}",
                    deriv[i]
                );
            }
        }
    }
}

#[test]
fn savgol_hand_checked_three_point_line() {
    // window 3, order 1: the centre value is the mean of the three samples, the derivative the
    // central difference (y[i+1] − y[i−1]) / (2 dt); the edges take the line through the first
    // (last) three samples: value (5 y0 + 2 y1 − y2)/6, slope (y2 − y0)/(2 dt).
    let sg = SavGol::new(3, 1).unwrap();
    let y = [1.0, 4.0, 2.0, 3.0];
    let s = sg.smooth(&y);
    let expected = [
        (5.0 + 8.0 - 2.0) / 6.0,
        7.0 / 3.0,
        3.0,
        (5.0 * 3.0 + 2.0 * 2.0 - 4.0) / 6.0,
    ];
    for (v, e) in s.iter().zip(expected) {
        assert!((v - e).abs() < 1e-14, "{s:?}");
    }
    let d = sg.derivative(&y, 0.5);
    let expected = [1.0, 1.0, -1.0, -1.0]; // (2 − 1)/1, (2 − 1)/1, (3 − 4)/1, (3 − 4)/1
    for (v, e) in d.iter().zip(expected) {
        assert!((v - e).abs() < 1e-14, "{d:?}");
    }
    // Order 0 (moving average): derivative identically zero, as scipy.
    assert_eq!(SavGol::new(3, 0).unwrap().derivative(&y, 0.5), vec![0.0; 4]);
}

#[test]
fn savgol_errors() {
    assert_eq!(SavGol::new(2, 0), Err(PreprocessError::WindowTooSmall { window: 2 }));
    assert_eq!(SavGol::new(8, 3), Err(PreprocessError::WindowEven { window: 8 }));
    assert_eq!(
        SavGol::new(7, 7),
        Err(PreprocessError::OrderTooHigh { window: 7, order: 7 })
    );
    let sg = SavGol::new(7, 2).unwrap();
    let e = sg.try_smooth(&[1.0; 6]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "signal of 6 samples is shorter than the Savitzky-Golay window 7"
    );
    assert!(matches!(
        sg.try_derivative(&[1.0; 10], f64::NAN),
        Err(PreprocessError::InvalidStep { .. })
    ));
    // Exactly one window long: centre from the centred fit, the rest from the same polynomial.
    assert_eq!(sg.try_smooth(&[2.0; 7]).unwrap().len(), 7);
}

#[test]
#[should_panic(expected = "must be odd")]
fn savgol_panicking_methods_report_invalid_fields() {
    SavGol { window: 6, order: 2 }.smooth(&[0.0; 20]);
}

// ---------------------------------------------------------------------------------------------
// Low-pass λ/(s+λ)

#[test]
fn lowpass_step_response_by_hand() {
    // λ h = ln 2 ⇒ a = e^{−λh} = 1/2. Input: a unit step at sample 1, held.
    // y0 = u0 = 0 (initial condition = first sample); y1 = a·0 + (1−a)·u0 = 0;
    // y2 = 0.5·0 + 0.5·1 = 0.5; y3 = 0.75; y4 = 0.875; y5 = 0.9375.
    let dt = 0.1;
    let lp = LowPass::new(std::f64::consts::LN_2 / dt).unwrap();
    assert!((lp.pole(dt) - 0.5).abs() < 1e-15);
    let y = lp.apply(&[0.0, 1.0, 1.0, 1.0, 1.0, 1.0], dt);
    for (v, e) in y.iter().zip([0.0, 0.0, 0.5, 0.75, 0.875, 0.9375]) {
        assert!((v - e).abs() < 1e-15, "{y:?}");
    }
}

#[test]
fn lowpass_matches_continuous_step_response_at_the_samples() {
    // Exact discretisation: for a step held from t₁, y(t_k) = 1 − e^{−λ (t_k − t₁)}, k ≥ 1.
    let (dt, lp) = (0.01, LowPass::default());
    assert_eq!(lp.lambda, PAPER_LAMBDA);
    let u: Vec<f64> = (0..600).map(|k| if k == 0 { 0.0 } else { 1.0 }).collect();
    let y = lp.apply(&u, dt);
    for (k, v) in y.iter().enumerate().skip(1) {
        let t = (k - 1) as f64 * dt;
        assert!((v - (1.0 - (-t).exp())).abs() < 1e-13, "sample {k}: {v}");
    }
    // One time constant (1/λ = 1 s) after the step: 63.2 %.
    assert!((y[101] - (1.0 - (-1.0f64).exp())).abs() < 1e-13);
}

#[test]
fn lowpass_is_linear_and_starts_in_steady_state() {
    let dt = 1.0 / 30.0;
    let lp = LowPass::new(2.5).unwrap();
    let a: Vec<f64> = (0..50).map(|k| (0.3 * k as f64).sin()).collect();
    let b: Vec<f64> = (0..50).map(|k| 0.02 * k as f64 - 1.0).collect();
    let sum: Vec<f64> = a.iter().zip(&b).map(|(x, y)| 2.0 * x - 3.0 * y).collect();
    let (fa, fb, fs) = (lp.apply(&a, dt), lp.apply(&b, dt), lp.apply(&sum, dt));
    for k in 0..50 {
        assert!((fs[k] - (2.0 * fa[k] - 3.0 * fb[k])).abs() < 1e-13);
    }
    assert_eq!(fa[0], a[0]);
    assert!(matches!(LowPass::new(-1.0), Err(PreprocessError::InvalidLambda { .. })));
    assert!(matches!(
        lp.try_apply(&a, 0.0),
        Err(PreprocessError::InvalidStep { .. })
    ));
}

#[test]
fn columnwise_applies_the_filter_to_each_column() {
    let dt = 0.05;
    let rows: Vec<[f64; 3]> = (0..30).map(|k| k as f64 * dt).map(|t| [t, t * t, 1.0]).collect();
    let sg = SavGol::new(5, 2).unwrap();
    let rates = try_columnwise(&rows, |y| sg.try_derivative(y, dt)).unwrap();
    for (k, r) in rates.iter().enumerate() {
        let t = k as f64 * dt;
        assert!(
            (r[0] - 1.0).abs() < 1e-10 && (r[1] - 2.0 * t).abs() < 1e-10 && r[2].abs() < 1e-10,
            "{k}: {r:?}"
        );
    }
    let lp = LowPass::default();
    let filtered = columnwise(&rows, |y| lp.apply(y, dt));
    let column1: Vec<f64> = rows.iter().map(|r| r[1]).collect();
    let expected = lp.apply(&column1, dt);
    for k in 0..rows.len() {
        assert_eq!(filtered[k][1], expected[k]);
        assert_eq!(filtered[k][2], 1.0);
    }
    let short = try_columnwise(&rows[..3], |y| sg.try_smooth(y));
    assert_eq!(short, Err(PreprocessError::SignalTooShort { len: 3, window: 5 }));
}

// ---------------------------------------------------------------------------------------------
// Metrics

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-14
}

#[test]
fn metrics_hand_checked() {
    // State A: O = [1, 2, 3, 6] (mean 3), P = [2, 2, 4, 4]; P − O = [1, 0, 1, −2].
    //   RMSE = √((1 + 0 + 1 + 4)/4) = √1.5;  MAE = (1 + 0 + 1 + 2)/4 = 1;
    //   d₁ = 1 − 4 / (Σ|P − 3| + Σ|O − 3|) = 1 − 4 / ((1+1+1+1) + (2+1+0+3)) = 1 − 4/10 = 0.6.
    // State B: O = P = [0, 0, 0, 0]: RMSE = MAE = 0, d₁ = 1 (0/0: exact prediction of a constant).
    // State C: O = [2, 2, 2, 2], P = [2, 2, 2, 3]: RMSE = √(1/4) = 0.5, MAE = 0.25,
    //   d₁ = 1 − 1 / (1 + 0) = 0.
    // Overall: RMSE = √((1.5 + 0 + 0.25)/3), MAE = (1 + 0 + 0.25)/3, d₁ = (0.6 + 1 + 0)/3.
    let observed = vec![
        vec![1.0, 0.0, 2.0],
        vec![2.0, 0.0, 2.0],
        vec![3.0, 0.0, 2.0],
        vec![6.0, 0.0, 2.0],
    ];
    let predicted = vec![
        vec![2.0, 0.0, 2.0],
        vec![2.0, 0.0, 2.0],
        vec![4.0, 0.0, 2.0],
        vec![4.0, 0.0, 3.0],
    ];
    let names: Vec<String> = ["a", "b", "c"].iter().map(|s| s.to_string()).collect();
    let m = compare(&predicted, &observed, &names).unwrap();
    assert_eq!(m.samples, 4);
    assert_eq!(m.names, names);
    for (got, want) in [
        (m.rmse[0], 1.5f64.sqrt()),
        (m.mae[0], 1.0),
        (m.d1[0], 0.6),
        (m.rmse[1], 0.0),
        (m.mae[1], 0.0),
        (m.d1[1], 1.0),
        (m.rmse[2], 0.5),
        (m.mae[2], 0.25),
        (m.d1[2], 0.0),
        (m.overall_rmse, (1.75f64 / 3.0).sqrt()),
        (m.overall_mae, 1.25 / 3.0),
        (m.overall_d1, 1.6 / 3.0),
    ] {
        assert!(close(got, want), "{got} vs {want}\n{m}");
    }
    // Overall RMSE is the RMSE of all entries pooled.
    let pooled = (predicted
        .iter()
        .flatten()
        .zip(observed.iter().flatten())
        .map(|(p, o)| (p - o).powi(2))
        .sum::<f64>()
        / 12.0)
        .sqrt();
    assert!(close(m.overall_rmse, pooled));

    // Arrays and &str names work too.
    let p: Vec<[f64; 1]> = vec![[1.0], [2.0]];
    let o: Vec<[f64; 1]> = vec![[1.0], [4.0]];
    let m1 = compare(&p, &o, &["x"]).unwrap();
    // P − O = [0, −2]: RMSE = √2, MAE = 1; Ō = 2.5, d₁ = 1 − 2/((1.5 + 0.5) + (1.5 + 1.5)) = 0.6.
    assert!(close(m1.rmse[0], 2f64.sqrt()) && close(m1.mae[0], 1.0) && close(m1.d1[0], 0.6));
}

#[test]
fn metrics_errors() {
    let names = ["x".to_string(), "vx".to_string()];
    let good = vec![vec![0.0, 1.0]; 3];
    let e = compare(&good, &good[..2], &names).unwrap_err();
    assert_eq!(
        e,
        MetricsError::SampleCountMismatch {
            predicted: 3,
            observed: 2
        }
    );
    let empty: Vec<Vec<f64>> = vec![];
    assert_eq!(compare(&empty, &empty, &names).unwrap_err(), MetricsError::Empty);
    assert_eq!(
        compare(&good, &good, &[] as &[String]).unwrap_err(),
        MetricsError::NoStates
    );

    let mut short = good.clone();
    short[1] = vec![0.0];
    let e = compare(&good, &short, &names).unwrap_err();
    assert_eq!(
        e,
        MetricsError::StateCountMismatch {
            series: Series::Observed,
            sample: 1,
            len: 1,
            expected: 2
        }
    );
    assert_eq!(
        e.to_string(),
        "observed sample 1 has 1 values, expected 2 (one per state name)"
    );

    let mut nan = good.clone();
    nan[2][1] = f64::NAN;
    let e = compare(&nan, &good, &names).unwrap_err();
    assert!(matches!(&e, MetricsError::NonFinite { series: Series::Predicted, sample: 2, state, .. } if state == "vx"));
    assert_eq!(e.to_string(), "predicted sample 2, state `vx`: non-finite value NaN");
    let mut inf = good.clone();
    inf[0][0] = f64::NEG_INFINITY;
    assert_eq!(
        compare(&good, &inf, &names).unwrap_err().to_string(),
        "observed sample 0, state `x`: non-finite value -inf"
    );
}

#[test]
fn metrics_serialise_to_json() {
    let m = compare(&[[1.0, 2.0], [2.0, 2.0]], &[[1.0, 2.0], [3.0, 2.0]], &["x", "y"]).unwrap();
    let v = serde_json::to_value(&m).unwrap();
    for key in [
        "names",
        "samples",
        "rmse",
        "mae",
        "d1",
        "overall_rmse",
        "overall_mae",
        "overall_d1",
    ] {
        assert!(v.get(key).is_some(), "{key} missing in {v}");
    }
    assert_eq!(v["names"], serde_json::json!(["x", "y"]));
    assert_eq!(v["d1"][1], 1.0);
    let back: metrics::Metrics = serde_json::from_value(v).unwrap();
    assert_eq!(back, m);
    let table = m.to_string();
    assert!(
        table.lines().count() == 4 && table.lines().last().unwrap().starts_with("overall"),
        "{table}"
    );
}

/// The paper's identification table (Table "Comparison of RMSE, MAE, and Concordance Index for
/// SINDy and PD"): per-state rows (RMSE, MAE, d₁) and the printed overall row "x". The overall
/// row computed by `overall` from the per-state rows must round to the printed one at 4
/// decimals (the table's precision).
#[test]
fn paper_identification_table_overall_row() {
    #[rustfmt::skip]
    let sindy = [
        (33.1389, 27.1978, 0.1300), (1.2704, 1.0249, 0.7435), (0.0399, 0.0334, 0.9861),
        (0.0179, 0.0133, 0.9927), (0.0252, 0.0172, 0.9916), (0.0042, 0.0035, 0.9964),
        (0.0290, 0.0231, 0.9075), (0.0238, 0.0194, 0.8333), (0.8033, 0.6057, 0.7498),
        (0.0438, 0.0285, 0.9597), (0.1788, 0.1224, 0.6744), (0.0049, 0.0033, 0.9966),
    ];
    #[rustfmt::skip]
    let pd = [
        (53.4461, 41.6780, 0.0887), (32.8757, 23.7101, 0.0779), (0.6811, 0.5703, 0.7705),
        (1.0154, 0.9151, 0.1133), (1.1049, 1.0193, 0.0515), (1.1453, 0.9436, 0.4652),
        (2.1226, 1.8431, 0.0575), (1.9420, 1.5267, 0.0355), (0.9464, 0.7830, 0.5414),
        (0.2639, 0.1991, 0.6997), (0.2468, 0.1714, 0.4701), (0.1684, 0.1343, 0.8588),
    ];
    for (label, rows, printed) in [
        ("SINDy", &sindy, ["9.5764", "2.4244", "0.8301"]),
        ("PD", &pd, ["18.1445", "6.1245", "0.3525"]),
    ] {
        let rmse: Vec<f64> = rows.iter().map(|r| r.0).collect();
        let mae: Vec<f64> = rows.iter().map(|r| r.1).collect();
        let d1: Vec<f64> = rows.iter().map(|r| r.2).collect();
        let all = overall(&rmse, &mae, &d1);
        let got = [
            format!("{:.4}", all.rmse),
            format!("{:.4}", all.mae),
            format!("{:.4}", all.d1),
        ];
        assert_eq!(got, printed, "{label}: {all:?}");
        // The other readings do not reproduce it: the mean RMSE and the RMS of the MAE.
        let mean_rmse = rmse.iter().sum::<f64>() / 12.0;
        let rms_mae = (mae.iter().map(|v| v * v).sum::<f64>() / 12.0).sqrt();
        assert_ne!(format!("{mean_rmse:.4}"), printed[0], "{label}");
        assert_ne!(format!("{rms_mae:.4}"), printed[1], "{label}");
        eprintln!(
            "{label}: overall RMSE {:.6} MAE {:.6} d1 {:.6}, printed {printed:?}",
            all.rmse, all.mae, all.d1
        );
    }
}

proptest! {
    // No regression files written into the source tree.
    #![proptest_config(ProptestConfig { failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn metrics_bounds(rows in prop::collection::vec(prop::array::uniform4(-100.0f64..100.0), 1..40)) {
        // Columns 0, 1: predicted; columns 2, 3: observed.
        let p: Vec<[f64; 2]> = rows.iter().map(|r| [r[0], r[1]]).collect();
        let o: Vec<[f64; 2]> = rows.iter().map(|r| [r[2], r[3]]).collect();
        let m = compare(&p, &o, &["a", "b"]).unwrap();
        for j in 0..2 {
            prop_assert!((0.0..=1.0).contains(&m.d1[j]));
            prop_assert!(m.rmse[j] >= m.mae[j] * (1.0 - 1e-12));
        }
        prop_assert!(m.overall_rmse >= m.overall_mae * (1.0 - 1e-12));
        // Exact prediction: zero error, perfect agreement.
        let exact = compare(&o, &o, &["a", "b"]).unwrap();
        prop_assert_eq!(exact.overall_rmse, 0.0);
        prop_assert_eq!(exact.overall_d1, 1.0);
    }
}
