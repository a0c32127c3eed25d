//! uavgen::analysis (the "where" of `uavgen diagnose`): spectra, coherence, whiteness,
//! cross-correlation, regimes and findings on small synthetic signals with known answers, and
//! the shipped SINDy model on M100 run 7 (skipped when ../shared is absent).

mod shared;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;
use uavgen::analysis::spectrum::{coherence, coherence_threshold, welch_psd};
use uavgen::analysis::stats::{chi2_sf, cross_correlation_at, demean_by_segment, segment_ranges};
use uavgen::analysis::whiteness::ljung_box;
use uavgen::analysis::{analyse, write_plots, WhereInput, WhereOptions};
use uavgen::discretize::{auto_substeps, discrete_step, Envelope};
use uavgen::identify::dataset::{build, DatasetOptions};
use uavgen::logs::read_log;
use uavgen::{load, ModelIr};

/// Standard normal samples (Box-Muller) from a seeded generator.
fn normal(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    (0..n)
        .map(|_| {
            let (a, b): (f64, f64) = (rng.gen::<f64>().max(1e-300), rng.gen());
            (-2.0 * a.ln()).sqrt() * (2.0 * std::f64::consts::PI * b).cos()
        })
        .collect()
}

/// A WhereInput with the given residual channels (one-step) and states/inputs, one segment per
/// start, hover states unless given.
fn input(channels: &[&str], residuals: Vec<Vec<f64>>, starts: Vec<usize>, dt: f64) -> WhereInput {
    let n = residuals[0].len();
    let mut time = vec![0.0; n];
    let ranges = segment_ranges(&starts, n);
    for r in &ranges {
        for k in r.clone() {
            time[k] = (k - r.start) as f64 * dt;
        }
    }
    WhereInput {
        dt,
        segment_starts: starts,
        channels: channels.iter().map(|s| s.to_string()).collect(),
        one_step: residuals,
        horizon: None,
        states: vec![[0.0; 12]; n],
        inputs: vec![[0.0; 4]; n],
        time_in_flight: time,
        battery_voltage: None,
        stale: vec![false; n],
        quality_notes: Vec::new(),
    }
}

#[test]
fn welch_psd_of_white_noise_integrates_to_its_variance() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let x = normal(&mut rng, 16384);
    let fs = 30.0;
    let (f, psd, windows) = welch_psd(&x, &segment_ranges(&[0], x.len()), fs, 128).unwrap();
    assert_eq!(windows, 16384 / 64 - 1);
    let df = f[1] - f[0];
    let total: f64 = psd.iter().sum::<f64>() * df;
    let var = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
    assert!((total - var).abs() < 0.03 * var, "∫PSD = {total}, variance {var}");
    // Flat at 2σ²/fs away from DC (which the per-window demeaning removes).
    let level = psd[2..psd.len() - 1].iter().sum::<f64>() / (psd.len() - 3) as f64;
    assert!((level - 2.0 / fs).abs() < 0.05 * 2.0 / fs, "level {level}");
}

#[test]
fn welch_psd_of_a_sine_peaks_at_its_frequency() {
    let (fs, f0, a) = (30.0, 4.1, 2.0);
    let x: Vec<f64> = (0..4000)
        .map(|k| a * (2.0 * std::f64::consts::PI * f0 * k as f64 / fs).sin())
        .collect();
    let (f, psd, _) = welch_psd(&x, &segment_ranges(&[0], x.len()), fs, 128).unwrap();
    let peak = (0..psd.len()).max_by(|i, j| psd[*i].total_cmp(&psd[*j])).unwrap();
    assert!((f[peak] - f0).abs() <= f[1] - f[0], "peak at {} Hz", f[peak]);
    // The power of the sine, a²/2, is all in the few bins around it.
    let df = f[1] - f[0];
    let near: f64 = psd
        .iter()
        .zip(&f)
        .filter(|(_, fk)| (**fk - f0).abs() < 3.0 * df)
        .map(|(p, _)| p * df)
        .sum();
    assert!((near - a * a / 2.0).abs() < 0.02 * a * a / 2.0, "power near f0 {near}");
}

#[test]
fn coherence_with_a_filtered_copy_is_one_and_with_independent_noise_is_small() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let n = 8192;
    let x = normal(&mut rng, n);
    let mut y = vec![0.0; n];
    for k in 2..n {
        y[k] = 0.5 * x[k] + 0.3 * x[k - 1] + 0.2 * x[k - 2];
    }
    let r = segment_ranges(&[0, 2], n)[1..].to_vec();
    let (_, c, windows) = coherence(&x, &y, &r, 30.0, 128).unwrap();
    let mean = c[1..].iter().sum::<f64>() / (c.len() - 1) as f64;
    assert!(mean > 0.99, "filtered copy: mean coherence {mean}");
    let z = normal(&mut rng, n);
    let (_, c, _) = coherence(&x, &z, &r, 30.0, 128).unwrap();
    let mean = c[1..].iter().sum::<f64>() / (c.len() - 1) as f64;
    // E[C] ≈ 1/K for K independent windows; 50 % overlap makes them slightly fewer.
    assert!(
        mean < 2.0 / windows as f64,
        "independent: mean coherence {mean} with {windows} windows"
    );
    let above = c[1..].iter().filter(|v| **v > coherence_threshold(windows)).count();
    assert!(above <= 8, "{above} of {} bins above the 95 % level", c.len() - 1);
}

#[test]
fn ljung_box_rejects_ar1_and_accepts_white_noise() {
    // scipy.stats.chi2.sf(10, 5)
    assert!((chi2_sf(10.0, 5.0) - 0.07523524614651217).abs() < 1e-14);
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let e = normal(&mut rng, 1000);
    let mut ar = vec![0.0; 1000];
    for k in 1..1000 {
        ar[k] = 0.8 * ar[k - 1] + e[k];
    }
    let (q, dof, p, acf) = ljung_box(&ar, &segment_ranges(&[0], 1000), 20);
    assert_eq!(dof, 20);
    assert!(p < 1e-12 && q > 500.0, "AR(1) 0.8: Q = {q}, p = {p}");
    assert!((acf[0] - 0.8).abs() < 0.06, "ρ1 = {}", acf[0]);
    let (q, _, p, acf) = ljung_box(&e, &segment_ranges(&[0], 1000), 20);
    assert!(p > 0.05, "white: Q = {q}, p = {p}");
    assert!(acf[0].abs() < 0.1);
}

#[test]
fn cross_correlation_finds_a_three_sample_delay_within_segments() {
    // Two segments; in each the roll_rate residual is u_roll delayed by 3 samples (0 before).
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let (n, split, dt) = (900, 500, 1.0 / 30.0);
    let u = normal(&mut rng, n);
    let mut r = vec![0.0; n];
    for (start, end) in [(0, split), (split, n)] {
        r[start + 3..end].copy_from_slice(&u[start..end - 3]);
    }
    let mut inp = input(&["roll_rate"], vec![r.clone()], vec![0, split], dt);
    for k in 0..n {
        inp.inputs[k][1] = u[k];
    }
    let rep = analyse(&inp, &WhereOptions::default());
    let x = rep
        .cross_correlation
        .iter()
        .find(|x| x.input == "u_roll" && x.channel == "roll_rate")
        .unwrap();
    assert_eq!(x.peak_lag, 3);
    assert!((x.peak_seconds - 0.1).abs() < 1e-12);
    assert!(x.peak_rho > 0.95 && x.significant, "{x:?}");
    // ρ(3) by hand over the pairs inside the segments only.
    let ranges = segment_ranges(&[0, split], n);
    let (ud, rd) = (demean_by_segment(&u, &ranges), demean_by_segment(&r, &ranges));
    let (mut s, mut uu, mut rr) = (0.0, 0.0, 0.0);
    for rg in &ranges {
        for k in rg.start..rg.end - 3 {
            s += ud[k] * rd[k + 3];
        }
        for k in rg.clone() {
            uu += ud[k] * ud[k];
            rr += rd[k] * rd[k];
        }
    }
    let by_hand = s / (uu * rr).sqrt();
    assert!((x.rho[15 + 3] - by_hand).abs() < 1e-12);
    // Ignoring the boundary would pair the end of segment 0 with the start of segment 1.
    let across = cross_correlation_at(&ud, &rd, &segment_ranges(&[0], n), 3);
    assert!((across - by_hand).abs() > 1e-6);
    let f = rep.findings();
    assert!(
        f.iter()
            .any(|s| s.starts_with("u_roll leads the roll_rate residual by 3 samples (0.1 s")),
        "{f:#?}"
    );
}

#[test]
fn drag_like_residual_grows_with_speed_and_correlates_with_v() {
    // vx sweeps ±4 m/s; the vx residual is −0.3 vx + noise; vy's residual is noise only.
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let (n, dt) = (3000, 1.0 / 30.0);
    let noise = normal(&mut rng, 2 * n);
    let vx: Vec<f64> = (0..n)
        .map(|k| {
            let t = k as f64 * dt;
            4.0 * (0.05 * t).sin() * (0.7 * t).sin()
        })
        .collect();
    let rx: Vec<f64> = (0..n).map(|k| -0.3 * vx[k] + 0.05 * noise[k]).collect();
    let ry: Vec<f64> = (0..n).map(|k| 0.05 * noise[n + k]).collect();
    let mut inp = input(&["vx", "vy"], vec![rx, ry], vec![0], dt);
    for k in 0..n {
        inp.states[k][6] = vx[k];
        inp.states[k][0] = if k > 0 { inp.states[k - 1][0] + vx[k] * dt } else { 0.0 };
    }
    let rep = analyse(&inp, &WhereOptions::default());
    let own = rep.own_state.iter().find(|o| o.channel == "vx").unwrap();
    assert!((own.slope + 0.3).abs() < 0.01 && own.r < -0.95, "{own:?}");
    let speed = rep.regimes.iter().find(|r| r.variable == "speed").unwrap();
    let s = &speed.one_step[0].stats;
    assert!(s.rmse_ratio.unwrap() > 5.0, "{s:?}");
    let f = rep.findings();
    let text = f.join("\n");
    assert!(text.contains("The vx residual grows with horizontal speed"), "{text}");
    assert!(text.contains("The vx residual correlates with vx (r = -0.99"), "{text}");
    assert!(text.contains("drag-like"), "{text}");
    assert!(!text.contains("The vy residual grows"), "{text}");
    // vx carries most of the normalised error.
    assert!(f[0].starts_with("Largest one-step gap first"), "{}", f[0]);
}

#[test]
fn regime_bins_on_a_synthetic_example() {
    // Height z visits 0 … 99 in a scrambled order (z = 37 k mod 100) so the residual is not
    // autocorrelated in time; the residual is 1 below z = 50 and 3 from there. 5 quantile bins of
    // 20 samples; bin means 1, 1, 2, 3, 3; η² = 20·(1+1+0+1+1) / 100 = 0.8.
    let n = 100;
    let z: Vec<f64> = (0..n).map(|k| ((37 * k) % 100) as f64).collect();
    let res: Vec<f64> = z.iter().map(|z| if *z < 50.0 { 1.0 } else { 3.0 }).collect();
    let mut inp = input(&["vz"], vec![res], vec![0], 0.1);
    for k in 0..n {
        inp.states[k][2] = z[k];
        inp.states[k][3] = 0.3;
        inp.states[k][4] = 0.4;
    }
    let rep = analyse(&inp, &WhereOptions::default());
    let keys: Vec<&str> = rep.regimes.iter().map(|r| r.variable.as_str()).collect();
    assert_eq!(
        keys,
        [
            "speed",
            "tilt",
            "height",
            "vertical_speed",
            "yaw_rate",
            "time_in_flight"
        ]
    );
    let h = &rep.regimes[2];
    let counts: Vec<usize> = h.bins.iter().map(|b| b.count).collect();
    assert_eq!(counts, vec![20; 5]);
    assert!((h.bins[1].lo - 19.8).abs() < 1e-12 && (h.bins[4].hi - 99.0).abs() < 1e-12);
    assert!((h.bins[0].median - 9.5).abs() < 1e-12);
    let s = &h.one_step[0].stats;
    let means: Vec<f64> = s.mean.iter().map(|m| m.unwrap()).collect();
    assert_eq!(means, vec![1.0, 1.0, 2.0, 3.0, 3.0]);
    assert!((s.rmse[2].unwrap() - 5f64.sqrt()).abs() < 1e-12);
    assert!((s.eta_squared - 0.8).abs() < 1e-12);
    assert!((s.rmse_ratio.unwrap() - 3.0).abs() < 1e-12);
    assert!(s.r.unwrap() > 0.8);
    // Tilt is constant: one bin holding every sample.
    let tilt = &rep.regimes[1];
    assert_eq!(tilt.bins.len(), 1);
    assert!((tilt.bins[0].lo - (0.3f64.cos() * 0.4f64.cos()).acos()).abs() < 1e-12);
    // Time in flight does not explain it (far less than height).
    assert!(rep.regimes[5].one_step[0].stats.eta_squared < 0.2);
    let f = rep.findings();
    assert!(
        f.iter()
            .any(|s| s.starts_with("The vz residual grows with height: RMSE 1 m/s² at 0–19.8 m → 3 m/s² at 79.2–99 m")),
        "{f:#?}"
    );
    // With a battery column the regime is added.
    inp.battery_voltage = Some((0..n).map(|k| 25.0 - 0.01 * k as f64).collect());
    let rep = analyse(&inp, &WhereOptions::default());
    assert_eq!(rep.regimes.last().unwrap().variable, "battery_voltage");
}

#[test]
fn report_serialises_and_plots_are_small_svgs() {
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let n = 1200;
    let chans = ["vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"];
    let res: Vec<Vec<f64>> = (0..6).map(|_| normal(&mut rng, n)).collect();
    let mut inp = input(&chans, res.clone(), vec![0, 700], 1.0 / 30.0);
    let mut h = res.clone();
    for s in &mut h {
        for k in (0..30).chain(700..730) {
            s[k] = f64::NAN;
        }
    }
    inp.horizon = Some(h);
    let u = normal(&mut rng, 4 * n);
    for k in 0..n {
        inp.inputs[k] = [u[k], u[n + k], u[2 * n + k], u[3 * n + k]];
        inp.states[k][6] = u[k] * 0.5;
        inp.stale[k] = k % 4 == 0;
    }
    inp.quality_notes.push("a note from the reader".into());
    let rep = analyse(&inp, &WhereOptions::default());
    assert_eq!(rep.horizon_steps, Some(30));
    assert_eq!(rep.segments, 2);
    assert!((rep.quality.stale_fraction - 0.25).abs() < 1e-12);
    let json = serde_json::to_value(&rep).unwrap();
    for key in [
        "samples",
        "segments",
        "dt",
        "channels",
        "inputs",
        "options",
        "horizon_steps",
        "one_step",
        "horizon",
        "regimes",
        "own_state",
        "spectrum",
        "whiteness",
        "cross_correlation",
        "response_lags",
        "quality",
    ] {
        assert!(json.get(key).is_some(), "missing {key}");
    }
    let text = serde_json::to_string(&rep).unwrap();
    assert!(!text.contains("NaN"));
    let f = rep.findings();
    assert!(
        f.iter().any(|s| s.starts_with("25 % of rows (300 of 1200) repeat")),
        "{f:#?}"
    );
    assert_eq!(f.last().unwrap(), "a note from the reader");
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("analysis_synthetic");
    let files = write_plots(&rep, &inp, &dir).unwrap();
    assert_eq!(files.len(), 3);
    for file in &files {
        let svg = std::fs::read_to_string(file).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.len() < 300_000,
            "{}: {} bytes",
            file.display(),
            svg.len()
        );
        assert!(svg.contains("roll_rate"), "{}", file.display());
    }
}

#[test]
fn tiny_and_empty_inputs_do_not_panic() {
    for n in [0, 1, 5] {
        let inp = input(&["vx"], vec![vec![0.5; n]], vec![0], 0.1);
        let rep = analyse(&inp, &WhereOptions::default());
        assert_eq!(rep.samples, n);
        assert!(rep.spectrum.is_none());
        assert!(!serde_json::to_string(&rep).unwrap().contains("NaN"));
        let _ = rep.findings();
    }
}

fn shared_run7() -> Option<PathBuf> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/flights/m100/m100_run7.csv");
    if path.is_file() {
        Some(path)
    } else {
        shared::skip(&path);
        None
    }
}

#[test]
fn m100_run7_sindy() {
    let Some(path) = shared_run7() else { return };
    let log = read_log(&path).unwrap();
    let repo = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let model = load(&repo.join("models/sindy_m100.json")).unwrap();
    let ir = ModelIr::new(&model);
    let options = DatasetOptions::default();
    let h = options.savgol.half_window();
    let data = build(std::slice::from_ref(&log), &options).unwrap();
    assert_eq!(data.segments.len(), 1);
    let seg = &data.segments[0];
    let full = &log.segments[0];
    let horizon = 30;
    let substeps = auto_substeps(&ir, seg.dt, &Envelope::default()).unwrap().substeps;
    let chans = ["vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"];
    let n = seg.t.len();
    let mut one_step = vec![vec![0.0; n]; 6];
    let mut hz = vec![vec![f64::NAN; n]; 6];
    let mut stale = vec![false; n];
    for k in 0..n {
        let f = ir.eval_f(&seg.x[k], &seg.u[k]);
        for c in 0..6 {
            one_step[c][k] = seg.dx[k][6 + c] - f[6 + c];
        }
        let kk = k + h; // index in the log's segment
        stale[k] = full.x[kk] == full.x[kk - 1];
        if kk >= horizon {
            let mut x = full.x[kk - horizon].to_vec();
            for j in kk - horizon..kk {
                x = discrete_step(&ir, &x, &full.u[j], seg.dt, substeps);
            }
            for c in 0..6 {
                hz[c][k] = full.x[kk][6 + c] - x[6 + c];
            }
        }
    }
    let input = WhereInput {
        dt: seg.dt,
        segment_starts: vec![0],
        channels: chans.iter().map(|s| s.to_string()).collect(),
        one_step,
        horizon: Some(hz),
        states: seg.x.clone(),
        inputs: seg.u.clone(),
        time_in_flight: seg.t.iter().map(|t| t - full.t[0]).collect(),
        battery_voltage: None,
        stale,
        quality_notes: log.report.warnings(),
    };
    let options = WhereOptions {
        horizon_steps: Some(horizon),
        ..WhereOptions::default()
    };
    let report = analyse(&input, &options);
    let findings = report.findings();
    println!("m100_run7, sindy_m100 ({n} samples, {substeps} RK4 substeps, horizon {horizon}):");
    for s in &findings {
        println!("- {s}");
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("analysis_run7");
    let files = write_plots(&report, &input, &dir).unwrap();
    let json = serde_json::to_string_pretty(&report).unwrap();
    std::fs::write(dir.join("where.json"), &json).unwrap();
    println!("plots and where.json in {}", dir.display());
    for f in &files {
        assert!(std::fs::metadata(f).unwrap().len() < 300_000);
    }
    // Robust facts only.
    assert!(!findings.is_empty());
    assert!(!json.contains("NaN"));
    for s in report.one_step.iter().chain(report.horizon.as_ref().unwrap()) {
        assert!(s.rmse.is_finite() && s.rmse > 0.0 && s.mean.is_finite() && s.std_error.is_finite());
        assert!(s.n_eff >= 1.0 && s.n_eff <= s.n as f64);
    }
    assert_eq!(report.horizon_steps, Some(horizon));
    // Inferred from the NaN prefix: the derivative data start h samples into the log.
    assert_eq!(
        analyse(&input, &WhereOptions::default()).horizon_steps,
        Some(horizon - h)
    );
    let trimmed = input.stale.iter().filter(|s| **s).count();
    assert_eq!(report.quality.stale_rows, trimmed);
    assert!((report.quality.stale_fraction - log.report.stale_fraction()).abs() < 0.01);
    let all = (1..full.len()).filter(|&k| full.x[k] == full.x[k - 1]).count();
    assert_eq!(all, log.report.stale_states());
    assert!(report
        .whiteness
        .iter()
        .all(|w| w.q.is_finite() && (0.0..=1.0).contains(&w.p_value)));
    let sp = report.spectrum.as_ref().unwrap();
    assert!(sp
        .channels
        .iter()
        .all(|c| c.psd.iter().all(|p| p.is_finite() && *p >= 0.0)));
}
