//! SINDy identification: hand-checked optimiser cases, the PySINDy cross-check
//! (tests/fixtures/sindy_crosscheck.json, written by scripts/pysindy_crosscheck.py), AIC selection, and
//! the model file a fit produces.

use nalgebra::DMatrix;
use serde_json::Value;
use uavgen::identify::dataset::{Dataset, SegmentData};
use uavgen::identify::sindy::{
    self, regress, AicSelection, Criterion, FittedRows, Library, LibraryKind, Optimizer, Regularizer, SindyOptions,
};
use uavgen::model::{DEFAULT_INPUTS, DEFAULT_STATES};

fn vars() -> Vec<String> {
    DEFAULT_STATES
        .iter()
        .chain(DEFAULT_INPUTS.iter())
        .map(|s| s.to_string())
        .collect()
}

/// Deterministic pseudo-random numbers in [-1, 1) (SplitMix64), independent of crate versions.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
    /// Approximately standard normal (sum of 12 uniforms).
    fn normal(&mut self) -> f64 {
        (0..12).map(|_| (self.next() + 1.0) / 2.0).sum::<f64>() - 6.0
    }
}

// ---------------------------------------------------------------- hand-checked cases

#[test]
fn stlsq_recovers_a_two_term_system_exactly() {
    // y = 2 a − 3 b with a third, irrelevant column c; no noise.
    let mut rng = Rng(1);
    let n = 50;
    let mut theta = DMatrix::zeros(n, 3);
    let mut y = DMatrix::zeros(n, 1);
    for k in 0..n {
        let (a, b, c) = (rng.next(), rng.next(), rng.next());
        theta[(k, 0)] = a;
        theta[(k, 1)] = b;
        theta[(k, 2)] = c;
        y[(k, 0)] = 2.0 * a - 3.0 * b;
    }
    for normalize in [false, true] {
        let r = regress(&theta, &y, &Optimizer::stlsq(0.1), normalize).unwrap();
        assert!((r.coef[(0, 0)] - 2.0).abs() < 1e-12, "{}", r.coef);
        assert!((r.coef[(0, 1)] + 3.0).abs() < 1e-12, "{}", r.coef);
        assert_eq!(r.coef[(0, 2)], 0.0);
        assert!(r.converged);
    }
}

#[test]
fn stlsq_threshold_removes_a_small_term() {
    // y = 1.0 a + 0.05 b: a threshold of 0.1 drops b, and the unbiased refit on {a} is the
    // least-squares slope Σ a y / Σ a², computed here by hand.
    let mut rng = Rng(7);
    let n = 40;
    let mut theta = DMatrix::zeros(n, 2);
    let mut y = DMatrix::zeros(n, 1);
    for k in 0..n {
        let (a, b) = (rng.next(), rng.next());
        theta[(k, 0)] = a;
        theta[(k, 1)] = b;
        y[(k, 0)] = a + 0.05 * b;
    }
    let opt = Optimizer::Stlsq {
        threshold: 0.1,
        alpha: 0.0,
        max_iter: 20,
        unbias: true,
    };
    let r = regress(&theta, &y, &opt, false).unwrap();
    let (ay, aa) = (0..n).fold((0.0, 0.0), |(s, q), k| {
        (s + theta[(k, 0)] * y[(k, 0)], q + theta[(k, 0)] * theta[(k, 0)])
    });
    assert_eq!(r.coef[(0, 1)], 0.0);
    assert!((r.coef[(0, 0)] - ay / aa).abs() < 1e-12);
    // A threshold below 0.05 keeps both, exactly.
    let r = regress(&theta, &y, &opt.with_sparsity(0.01), false).unwrap();
    assert!((r.coef[(0, 0)] - 1.0).abs() < 1e-12 && (r.coef[(0, 1)] - 0.05).abs() < 1e-12);
}

#[test]
fn sr3_prox_definitions() {
    // One orthonormal column: the SR3 fixed point is prox(w) with w = (y·θ + v/ν)/(1 + 1/ν).
    // L1 with λν = 0.25: v = w − 0.25 and w = (1 + v)/2 → v* = 0.5 for y·θ = 1 (ν = 1).
    let theta = DMatrix::from_column_slice(2, 1, &[1.0, 0.0]);
    let y = DMatrix::from_column_slice(2, 1, &[1.0, 0.0]);
    let l1 = Optimizer::Sr3 {
        regularizer: Regularizer::L1,
        reg_weight_lam: 0.25,
        relax_coeff_nu: 1.0,
        max_iter: 10_000,
        tol: 1e-14,
        unbias: false,
    };
    let r = regress(&theta, &y, &l1, false).unwrap();
    assert!((r.coef[(0, 0)] - 0.5).abs() < 1e-12, "{}", r.coef);
    // L0 hard-thresholds at √(2λν): λ = 0.5 → 1.0 ≥ w = 1 removes it; λ = 0.4 → √0.8 < 1 keeps it.
    let l0 = Optimizer::Sr3 {
        regularizer: Regularizer::L0,
        reg_weight_lam: 0.5,
        relax_coeff_nu: 1.0,
        max_iter: 100,
        tol: 1e-14,
        unbias: false,
    };
    assert_eq!(regress(&theta, &y, &l0, false).unwrap().coef[(0, 0)], 0.0);
    let r = regress(&theta, &y, &l0.with_sparsity(0.4), false).unwrap();
    assert!((r.coef[(0, 0)] - 1.0).abs() < 1e-12);
}

#[test]
fn invalid_settings_are_rejected() {
    let theta = DMatrix::from_element(3, 1, 1.0);
    let y = DMatrix::from_element(3, 1, 1.0);
    for bad in [
        Optimizer::stlsq(-1.0),
        Optimizer::stlsq(f64::NAN),
        Optimizer::Sr3 {
            regularizer: Regularizer::L0,
            reg_weight_lam: 0.1,
            relax_coeff_nu: 0.0,
            max_iter: 10,
            tol: 1e-5,
            unbias: false,
        },
    ] {
        assert!(regress(&theta, &y, &bad, false).is_err(), "{bad:?}");
    }
    let zero = DMatrix::from_element(3, 1, 0.0);
    assert!(regress(&zero, &y, &Optimizer::stlsq(0.1), true).is_err());
}

// ---------------------------------------------------------------- PySINDy cross-check

fn fixture() -> Value {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/sindy_crosscheck.json");
    serde_json::from_str(&std::fs::read_to_string(path).expect("fixture present")).unwrap()
}

fn matrix(v: &Value) -> DMatrix<f64> {
    let rows: Vec<Vec<f64>> = serde_json::from_value(v.clone()).unwrap();
    let (r, c) = (rows.len(), rows[0].len());
    DMatrix::from_fn(r, c, |i, j| rows[i][j])
}

fn optimizer_from(settings: &Value) -> (Optimizer, bool) {
    let f = |k: &str| settings[k].as_f64().unwrap();
    let max_iter = settings["max_iter"].as_u64().unwrap() as usize;
    let unbias = settings["unbias"].as_bool().unwrap();
    let opt = match settings["optimizer"].as_str().unwrap() {
        "STLSQ" => Optimizer::Stlsq {
            threshold: f("threshold"),
            alpha: f("alpha"),
            max_iter,
            unbias,
        },
        "SR3" => Optimizer::Sr3 {
            regularizer: match settings["regularizer"].as_str().unwrap() {
                "L0" => Regularizer::L0,
                "L1" => Regularizer::L1,
                r => panic!("regularizer {r}"),
            },
            reg_weight_lam: f("reg_weight_lam"),
            relax_coeff_nu: f("relax_coeff_nu"),
            max_iter,
            tol: f("tol"),
            unbias,
        },
        o => panic!("optimizer {o}"),
    };
    (opt, settings["normalize_columns"].as_bool().unwrap())
}

#[test]
fn pysindy_crosscheck() {
    let fx = fixture();
    let x = matrix(&fx["x"]);
    let u = matrix(&fx["u"]);
    let dx = matrix(&fx["dx"]);
    let n = x.nrows();
    let values: Vec<Vec<f64>> = (0..n)
        .map(|k| x.row(k).iter().chain(u.row(k).iter()).copied().collect())
        .collect();
    let vars = vars();
    let mut report = Vec::new();
    for case in fx["cases"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let lib_name = case["library"].as_str().unwrap();
        let terms: Vec<String> = serde_json::from_value(fx["libraries"][lib_name].clone()).unwrap();
        let kind = if lib_name == "paper" {
            LibraryKind::Paper
        } else {
            LibraryKind::Physics
        };
        assert_eq!(
            terms,
            kind.terms(),
            "{name}: the fixture's library is uavgen's {lib_name} library"
        );
        let lib = Library::new(terms, &vars).unwrap();
        let theta = lib.matrix(values.iter().map(|v| v.as_slice()));
        // Our term evaluation gives PySINDy's Θ (column norms to 1e-12).
        let norms: Vec<f64> = serde_json::from_value(fx["theta_column_norms"][lib_name].clone()).unwrap();
        for (j, want) in norms.iter().enumerate() {
            let got = theta.column(j).norm();
            assert!(
                (got - want).abs() <= 1e-12 * want.abs(),
                "{name}: Θ column {j}: {got} vs {want}"
            );
        }
        let targets: Vec<String> = serde_json::from_value(case["targets"].clone()).unwrap();
        let cols: Vec<usize> = targets
            .iter()
            .map(|t| DEFAULT_STATES.iter().position(|s| s == t).unwrap())
            .collect();
        let y = dx.select_columns(&cols);
        let (opt, normalize) = optimizer_from(&case["settings"]);
        let r = regress(&theta, &y, &opt, normalize).unwrap();
        let want = matrix(&case["coef"]);
        assert_eq!(r.coef.shape(), want.shape(), "{name}");
        assert_eq!(
            r.iterations as u64,
            case["iterations"].as_u64().unwrap(),
            "{name}: iterations"
        );
        assert_eq!(r.converged, case["converged"].as_bool().unwrap(), "{name}: converged");
        let mut worst: f64 = 0.0;
        for i in 0..want.nrows() {
            for j in 0..want.ncols() {
                let (a, b) = (r.coef[(i, j)], want[(i, j)]);
                assert_eq!(
                    a != 0.0,
                    b != 0.0,
                    "{name}: support differs at ({}, {})",
                    targets[i],
                    lib.names[j]
                );
                if b != 0.0 {
                    let rel = (a - b).abs() / b.abs();
                    worst = worst.max(rel);
                    assert!(
                        rel <= 1e-6,
                        "{name}: ({}, {}): {a} vs PySINDy {b}",
                        targets[i],
                        lib.names[j]
                    );
                }
            }
        }
        let nnz = want.iter().filter(|&&v| v != 0.0).count();
        report.push(format!("{name}: {nnz} non-zeros, max rel diff {worst:.2e}"));
    }
    eprintln!(
        "PySINDy {} cross-check:\n  {}",
        fx["pysindy_version"],
        report.join("\n  ")
    );
}

// ---------------------------------------------------------------- AIC sweep and the model file

/// Samples of a toy vehicle with known sparse dynamics in the physics library, plus noise.
fn toy_dataset(n: usize, noise: f64, seed: u64) -> Dataset {
    let mut rng = Rng(seed);
    let mut seg = SegmentData {
        dt: 0.02,
        ..Default::default()
    };
    for k in 0..n {
        let mut x = [0.0; 12];
        let mut u = [0.0; 4];
        let scale = [5.0, 5.0, 5.0, 1.2, 1.2, 3.0, 2.0, 2.0, 1.0, 1.5, 1.5, 1.5];
        for i in 0..12 {
            x[i] = scale[i] * rng.next();
        }
        let uscale = [1.0, 0.5, 0.5, 1.0];
        for i in 0..4 {
            u[i] = uscale[i] * rng.next();
        }
        let (roll, pitch, yaw) = (x[3], x[4], x[5]);
        let mut dx = [0.0; 12];
        dx[..6].copy_from_slice(&x[6..]);
        // Thrust direction of a tilted vehicle holding its weight (small-angle product form).
        dx[6] = -0.4 * x[6] + 9.81 * (pitch.sin() * yaw.cos() + roll.sin() * yaw.sin());
        dx[7] = -0.4 * x[7] + 9.81 * (pitch.sin() * yaw.sin() - roll.sin() * yaw.cos());
        dx[8] = 2.0 * u[0] - 2.0 * x[8];
        dx[9] = 16.0 * (u[1] - roll) - 6.0 * x[9];
        dx[10] = 16.0 * (u[2] - pitch) - 6.0 * x[10];
        dx[11] = 3.0 * (u[3] - x[11]);
        for d in dx.iter_mut().skip(6) {
            *d += noise * rng.normal();
        }
        seg.t.push(k as f64 * 0.02);
        seg.x.push(x);
        seg.u.push(u);
        seg.dx.push(dx);
    }
    Dataset { segments: vec![seg] }
}

/// The true number of terms per dynamic row of `toy_dataset`.
const TRUE_TERMS: [(&str, &[&str]); 6] = [
    ("vx", &["vx", "sin(pitch)*cos(yaw)", "sin(roll)*sin(yaw)"]),
    ("vy", &["vy", "sin(pitch)*sin(yaw)", "sin(roll)*cos(yaw)"]),
    ("vz", &["vz", "u_vz"]),
    ("roll_rate", &["roll", "roll_rate", "u_roll"]),
    ("pitch_rate", &["pitch", "pitch_rate", "u_pitch"]),
    ("yaw_rate", &["yaw_rate", "u_yaw_rate"]),
];

fn sweep_values() -> Vec<f64> {
    (0..=24).map(|i| 10f64.powf(-3.0 + 0.125 * i as f64)).collect() // 1e-3 .. 1
}

fn stlsq_sweep(selection: AicSelection) -> SindyOptions {
    SindyOptions {
        optimizer: Optimizer::Stlsq {
            threshold: 0.0,
            alpha: 1e-6,
            max_iter: 20,
            unbias: true,
        },
        normalize_columns: false,
        sweep: Some(sweep_values()),
        selection,
        ..Default::default()
    }
}

/// (state, chosen terms sorted, true terms sorted) per dynamic row.
fn chosen_vs_true(fit: &sindy::SindyFit) -> Vec<(String, Vec<String>, Vec<String>)> {
    TRUE_TERMS
        .iter()
        .map(|(state, terms)| {
            let mut got: Vec<String> = fit
                .file
                .coefficients
                .iter()
                .filter(|c| c.state == *state)
                .map(|c| c.term.clone())
                .collect();
            let mut want: Vec<String> = terms.iter().map(|s| s.to_string()).collect();
            got.sort();
            want.sort();
            (state.to_string(), got, want)
        })
        .collect()
}

#[test]
fn aic_sweep_picks_the_true_sparsity_on_exact_data() {
    // Without noise every superset of the true support fits to rounding error; the AIC floor
    // (σ² ≥ 1e-24 mean ẋ²) makes those fits tie and the 2k penalty picks the true support.
    let data = toy_dataset(1500, 0.0, 42);
    for selection in [AicSelection::PerRow, AicSelection::Total] {
        let mut options = stlsq_sweep(selection);
        // Threshold 0 keeps every term (the spurious ones at rounding level).
        options.sweep.as_mut().unwrap().insert(0, 0.0);
        let fit = sindy::fit(&data, &options, "toy", Value::Null).unwrap();
        // The smallest threshold keeps spurious terms: the sweep had a choice to make.
        assert!(
            fit.sweep[0].rows.iter().map(|r| r.terms).sum::<usize>() > 16,
            "{selection:?}"
        );
        for (state, got, want) in chosen_vs_true(&fit) {
            assert_eq!(got, want, "{selection:?} {state}");
        }
    }
}

#[test]
fn information_criteria_on_noisy_data() {
    // σ = 0.05 noise on the derivatives. BIC picks the true support in all 6 rows. AIC never drops
    // a true term but keeps spurious ones in most rows (88 terms of the 297 at the smallest
    // threshold, 1 row exact): with ~60 candidates on the threshold path, the largest chance
    // correlations reduce N ln RSS by more than 2 per term (see docs/sindy.md).
    // (Total selection, one threshold for all rows, is exercised on exact data above; on noisy data
    // its compromise threshold keeps spurious terms in rows with small coefficients.)
    let data = toy_dataset(1500, 0.05, 42);
    for selection in [AicSelection::PerRow] {
        let options = SindyOptions {
            criterion: Criterion::Bic,
            ..stlsq_sweep(selection)
        };
        let fit = sindy::fit(&data, &options, "toy", Value::Null).unwrap();
        let rows = chosen_vs_true(&fit);
        for (state, got, want) in &rows {
            assert!(
                want.iter().all(|t| got.contains(t)),
                "BIC {state}: {got:?} lacks a true term of {want:?}"
            );
            assert!(got.len() <= want.len() + 1, "BIC {selection:?} {state}: {got:?}");
        }
        let exact = rows.iter().filter(|(_, g, w)| g == w).count();
        eprintln!("BIC {selection:?}: {exact} of 6 rows exact");
        assert!(exact == 6, "BIC {selection:?}: {rows:?}");
    }
    let fit = sindy::fit(&data, &stlsq_sweep(AicSelection::PerRow), "toy", Value::Null).unwrap();
    let densest: usize = fit.sweep[0].rows.iter().map(|r| r.terms).sum();
    let chosen: usize = fit.rows.iter().map(|r| r.terms).sum();
    let rows = chosen_vs_true(&fit);
    let exact = rows.iter().filter(|(_, g, w)| g == w).count();
    for (state, got, want) in &rows {
        assert!(
            want.iter().all(|t| got.contains(t)),
            "AIC {state}: {got:?} lacks a true term of {want:?}"
        );
    }
    eprintln!("AIC per row: {exact} of 6 rows exact, {chosen} terms chosen of {densest} at the smallest threshold");
    assert!(exact >= 1 && chosen * 3 < densest, "{rows:?}");
}

#[test]
fn fit_writes_a_valid_model_file() {
    let data = toy_dataset(800, 0.01, 3);
    for (library, rows, optimizer) in [
        (LibraryKind::Physics, FittedRows::Dynamic, Optimizer::stlsq(0.5)),
        (
            LibraryKind::Paper,
            FittedRows::All,
            Optimizer::sr3(Regularizer::L0, 0.125),
        ),
        (
            LibraryKind::Paper,
            FittedRows::Dynamic,
            Optimizer::sr3(Regularizer::L1, 0.5),
        ),
    ] {
        let options = SindyOptions {
            library,
            rows,
            optimizer,
            normalize_columns: true,
            ..Default::default()
        };
        let prov = serde_json::json!({"data": ["toy.csv"]});
        let fit = sindy::fit(&data, &options, "toy_fit", prov).unwrap();
        let text = fit.to_json();
        let model = uavgen::model::parse(&text, "toy_fit.json").unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(model.name, "toy_fit");
        let p = &model.provenance;
        assert_eq!(p["data"][0], "toy.csv");
        assert_eq!(p["method"], "sindy");
        assert_eq!(p["library"], library.name());
        assert!(p["fit"]["derivative_rmse"]["vx"].is_number());
        let n_targets = if rows == FittedRows::All { 12 } else { 6 };
        assert_eq!(fit.targets.len(), n_targets);
        assert_eq!(fit.file.kinematic.is_empty(), rows == FittedRows::All);
        assert_eq!(fit.file.library.len(), library.terms().len());
        // Every coefficient entry is the matching entry of Ξ.
        for c in &fit.file.coefficients {
            let t = fit.targets.iter().position(|s| *s == c.state).unwrap();
            let j = fit.file.library.iter().position(|s| *s == c.term).unwrap();
            assert_eq!(fit.coefficients[(t, j)], c.coefficient);
        }
    }
}

#[test]
fn physics_fit_recovers_the_toy_vehicle() {
    let data = toy_dataset(1000, 0.0, 11);
    let options = SindyOptions {
        optimizer: Optimizer::Stlsq {
            threshold: 0.05,
            alpha: 0.0,
            max_iter: 20,
            unbias: true,
        },
        normalize_columns: false,
        ..Default::default()
    };
    let fit = sindy::fit(&data, &options, "toy", Value::Null).unwrap();
    let get = |s: &str, t: &str| {
        fit.file
            .coefficients
            .iter()
            .find(|c| c.state == s && c.term == t)
            .map(|c| c.coefficient)
    };
    assert!((get("vx", "sin(pitch)*cos(yaw)").unwrap() - 9.81).abs() < 1e-9);
    assert!((get("vy", "sin(roll)*cos(yaw)").unwrap() + 9.81).abs() < 1e-9);
    assert!((get("roll_rate", "u_roll").unwrap() - 16.0).abs() < 1e-9);
    assert_eq!(fit.file.coefficients.len(), 16);
    assert!(fit.rows.iter().all(|r| r.r2 > 1.0 - 1e-12));
}

#[test]
fn fit_errors() {
    let empty = Dataset::default();
    assert!(matches!(
        sindy::fit(&empty, &SindyOptions::default(), "m", Value::Null),
        Err(sindy::SindyError::Empty)
    ));
    let data = toy_dataset(200, 0.0, 1);
    assert!(sindy::fit(&data, &SindyOptions::default(), " ", Value::Null).is_err());
    let bad_sweep = SindyOptions {
        sweep: Some(vec![]),
        ..Default::default()
    };
    assert!(sindy::fit(&data, &bad_sweep, "m", Value::Null).is_err());
    let few = toy_dataset(30, 0.0, 1);
    assert!(matches!(
        sindy::fit(&few, &SindyOptions::default(), "m", Value::Null),
        Err(sindy::SindyError::TooFewSamples { .. })
    ));
}
