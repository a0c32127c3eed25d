//! The generated MPC against the generic reference solver (interpreted model,
//! sparse QP by clarabel): one RTI step on 1000 random instances per model,
//! 900-step closed loops on the paper's trajectories, and SQP to convergence.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use uavgen::reference::{GenericMpc, MpcProblem, ReferenceError};
use uavgen::MpcOptions;
use uavgen_tests::{envelope_points, shipped_model, INPUT_BOUNDS, STATE_BOUNDS};

/// The generic solver for a shipped model with the default options, except the input-rate weights:
/// the crate's own `R_DELTA` (the default, 50 on u_roll and u_pitch, for every shipped crate;
/// `default_rate_weight_in_the_riccati_crate` checks it for the stage-wise one).
fn generic(model: &str, dt: f64, substeps: usize, horizon: usize, r_delta: &[f64]) -> GenericMpc {
    let m = shipped_model(model);
    let mut options = MpcOptions::defaults(&m);
    options.r_delta = r_delta.to_vec();
    GenericMpc::new(
        uavgen::ModelIr::new(&m),
        MpcProblem {
            horizon,
            dt,
            substeps,
            options,
        },
    )
}

/// The paper's trajectories (positions only; Q weighs nothing else): the runtime's own formulas.
fn trajectory(name: &str, t: f64) -> [f64; 3] {
    use uavgen_runtime::Trajectory;
    match name {
        "sinusoidal" => Trajectory::Sinusoidal,
        "circular" => Trajectory::Circular,
        "spiral" => Trajectory::Spiral,
        _ => unreachable!(),
    }
    .position(t)
}

macro_rules! comparisons {
    ($mod_name:ident, $krate:ident, $model:literal, hovers: $hovers:literal) => {
        mod $mod_name {
            use super::*;
            use $krate::{Mpc, Status, DT, N, NU, NX, SUBSTEPS};

            fn window(name: &str, t: f64) -> [[f64; NX]; N + 1] {
                let mut r = [[0.0; NX]; N + 1];
                for (k, row) in r.iter_mut().enumerate() {
                    let p = trajectory(name, t + k as f64 * DT);
                    row[..3].copy_from_slice(&p);
                }
                r
            }

            fn max_plan_difference(a: &[[f64; NU]; N], b: &[Vec<f64>]) -> f64 {
                let mut worst: f64 = 0.0;
                for k in 0..N {
                    for i in 0..NU {
                        worst = worst.max((a[k][i] - b[k][i]).abs());
                    }
                }
                worst
            }

            #[test]
            fn one_rti_step_on_random_instances() {
                let mut rng = ChaCha8Rng::seed_from_u64(2024);
                let mut reference_solver = generic($model, DT, SUBSTEPS, N, &$krate::R_DELTA);
                let points = envelope_points(1000 * (N + 2), 5);
                let mut worst: f64 = 0.0;
                for instance in 0..1000 {
                    let p = &points[instance * (N + 2)..(instance + 1) * (N + 2)];
                    // Guess: envelope states near x0 (a perturbed trajectory) and inputs within bounds.
                    let x0 = p[0].0;
                    let mut xs = [[0.0; NX]; N + 1];
                    let mut us = [[0.0; NU]; N];
                    for k in 0..=N {
                        for i in 0..NX {
                            xs[k][i] = x0[i] + 0.1 * p[k + 1].0[i] / STATE_BOUNDS[i].max(1.0);
                        }
                    }
                    for k in 0..N {
                        us[k] = p[k + 1].1;
                    }
                    let mut reference = [[0.0; NX]; N + 1];
                    for row in reference.iter_mut() {
                        for i in 0..3 {
                            row[i] = x0[i] + rng.gen_range(-3.0..3.0);
                        }
                    }
                    let mut mpc = Mpc::new();
                    assert!(mpc.set_guess(&xs, &us));
                    let s = mpc.solve(&x0, &reference);
                    // A random x₀ may leave a declared envelope (sindy_m100, pd_m100: the M100
                    // logs' vz within -1.7..1.8 m/s); the step is taken all the same.
                    let inside = (0..NX).all(|i| x0[i] >= $krate::ENVELOPE_LO[i] && x0[i] <= $krate::ENVELOPE_HI[i]);
                    let expected = if inside { Status::Solved } else { Status::OutOfEnvelope };
                    assert_eq!(s.status, expected, "instance {instance}");
                    reference_solver.set_guess(xs.iter().map(|x| x.to_vec()).collect(), us.iter().map(|u| u.to_vec()).collect());
                    let r: Vec<Vec<f64>> = reference.iter().map(|x| x.to_vec()).collect();
                    let g = reference_solver.rti_step(&x0, &r).unwrap_or_else(|e| panic!("instance {instance}: {e}"));
                    let d = max_plan_difference(mpc.planned_inputs(), reference_solver.planned_inputs());
                    assert!(d <= 1e-6, "instance {instance}: planned inputs differ by {d:e}");
                    assert!((s.cost - g.cost).abs() <= 1e-6 * g.cost.abs().max(1.0), "cost {} vs {}", s.cost, g.cost);
                    worst = worst.max(d);
                }
                eprintln!("{}: 1000 random RTI steps, worst planned-input difference {worst:.1e}", $model);
            }

            #[test]
            fn closed_loops_on_the_paper_trajectories() {
                for name in ["sinusoidal", "circular", "spiral"] {
                    let mut mpc = Mpc::new();
                    let mut reference_solver = generic($model, DT, SUBSTEPS, N, &$krate::R_DELTA);
                    let mut x = [0.0; NX];
                    x[..3].copy_from_slice(&[3.0, 3.0, 5.0]);
                    let mut worst: f64 = 0.0;
                    let mut uncertified = 0;
                    for step in 0..900 {
                        let t = step as f64 * DT;
                        let r = window(name, t);
                        if !$hovers {
                            // The paper's model falls and its RTI iteration is not contractive:
                            // rounding differences between the two solvers' guesses grow
                            // (×10 every ~5 steps once it saturates). Each step is compared
                            // from the same guess instead.
                            reference_solver.set_guess(
                                mpc.predicted_states().iter().map(|x| x.to_vec()).collect(),
                                mpc.planned_inputs().iter().map(|u| u.to_vec()).collect(),
                            );
                        }
                        let s = mpc.solve(&x, &r);
                        let rv: Vec<Vec<f64>> = r.iter().map(|x| x.to_vec()).collect();
                        let g = match reference_solver.rti_step(&x, &rv) {
                            Ok(g) => g,
                            // The falling paper model, compared step by step from the same guess:
                            // where clarabel cannot solve the (ill-conditioned) QP to its tolerances,
                            // the step is not compared; the generated solver must still solve it, and
                            // such steps must stay rare.
                            Err(ReferenceError::Qp(e)) if !$hovers && e.contains("AlmostSolved") => {
                                assert_eq!(s.status, Status::Solved, "{name} step {step}");
                                uncertified += 1;
                                assert!(uncertified <= 9, "{name}: more than 1 % of the steps uncertified");
                                x = $krate::discrete_dynamics(&x, &s.u0);
                                mpc.shift();
                                reference_solver.shift();
                                continue;
                            }
                            Err(e) => panic!("{name} step {step}: {e}"),
                        };
                        if std::env::var("UAVGEN_TRACE").is_ok() && step % 10 == 0 {
                            let d = max_plan_difference(mpc.planned_inputs(), reference_solver.planned_inputs());
                            eprintln!("{name} {step}: plan diff {d:.1e} qp {} {:?}", s.qp_iterations, s.status);
                        }
                        for i in 0..NU {
                            let d = (s.u0[i] - g.u0[i]).abs();
                            worst = worst.max(d);
                            assert!(d <= 1e-6, "{} {name} step {step}: u0[{i}] {} vs {}", $model, s.u0[i], g.u0[i]);
                        }
                        x = $krate::discrete_dynamics(&x, &s.u0);
                        mpc.shift();
                        reference_solver.shift();
                    }
                    eprintln!(
                        "{} {name}: 900 closed-loop steps, worst u0 difference {worst:.1e}, {uncertified} not certified by clarabel",
                        $model
                    );
                }
            }

            #[test]
            fn sqp_iterations_at_fixed_x0_match_the_generic_ones() {
                // Repeated prepare/feedback without shift = full-step Gauss-Newton SQP.
                let mut x0 = [0.0; NX];
                x0[..3].copy_from_slice(&[3.0, 3.0, 5.0]);
                let r = window("circular", 0.0);
                let rv: Vec<Vec<f64>> = r.iter().map(|x| x.to_vec()).collect();
                let mut mpc = Mpc::new();
                let mut reference_solver = generic($model, DT, SUBSTEPS, N, &$krate::R_DELTA);
                let mut previous = *mpc.planned_inputs();
                let mut converged_after = None;
                for iteration in 1..=300 {
                    mpc.solve(&x0, &r);
                    reference_solver.rti_step(&x0, &rv).unwrap();
                    let d = max_plan_difference(mpc.planned_inputs(), reference_solver.planned_inputs());
                    assert!(d <= 1e-6, "{} SQP iteration {iteration}: plans differ by {d:e}", $model);
                    let change = previous
                        .iter()
                        .zip(mpc.planned_inputs())
                        .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
                        .fold(0.0, f64::max);
                    previous = *mpc.planned_inputs();
                    if change < 1e-10 {
                        converged_after = Some(iteration);
                        break;
                    }
                }
                eprintln!("{}: SQP at fixed x0: {converged_after:?} iterations to converge; every iterate matched the generic one", $model);
                if $hovers {
                    let iterations = converged_after.unwrap_or_else(|| panic!("{}: SQP did not converge", $model));
                    // The generic full SQP reaches the same optimum on its own.
                    let mut fresh = generic($model, DT, SUBSTEPS, N, &$krate::R_DELTA);
                    let (_, generic_iterations) = fresh.solve_to_convergence(&x0, &rv, 1e-10, 300).unwrap();
                    let d = max_plan_difference(mpc.planned_inputs(), fresh.planned_inputs());
                    assert!(d <= 1e-6, "{}: converged plans differ by {d:e}", $model);
                    eprintln!("{}: generated {iterations} / generic {generic_iterations} iterations, optima differ by {d:.1e}", $model);
                    // The optimum is a true trajectory of the model.
                    let xs = mpc.predicted_states();
                    for k in 0..N {
                        let next = $krate::discrete_dynamics(&xs[k], &mpc.planned_inputs()[k]);
                        for i in 0..NX {
                            assert!((next[i] - xs[k + 1][i]).abs() < 1e-6);
                        }
                    }
                }
            }

            #[test]
            fn invalid_input_keeps_the_plan() {
                let mut mpc = Mpc::new();
                let mut x0 = [0.0; NX];
                x0[..3].copy_from_slice(&[3.0, 3.0, 5.0]);
                let r = window("circular", 0.0);
                mpc.solve(&x0, &r);
                let plan = *mpc.planned_inputs();
                // The input sent: each channel's plan at its lead (stage 0 without delays).
                let sent: [f64; NU] = core::array::from_fn(|i| plan[$krate::INPUT_LEAD[i]][i]);
                let mut bad = x0;
                bad[4] = f64::NAN;
                let s = mpc.solve(&bad, &r);
                assert_eq!(s.status, Status::InvalidInput);
                assert_eq!(s.u0, sent);
                assert_eq!(*mpc.planned_inputs(), plan);
                let mut bad_r = r;
                bad_r[N][0] = f64::INFINITY;
                let s = mpc.solve(&x0, &bad_r);
                assert_eq!(s.status, Status::InvalidInput);
                assert_eq!(s.u0, sent);
                for i in 0..NU {
                    assert!(s.u0[i] >= $krate::U_MIN[i] && s.u0[i] <= $krate::U_MAX[i]);
                }
            }

            /// A broken estimator (positions of 1e6..1e30 m, a speed of 1e3 m/s) or a reference
            /// far away is flagged, never `Solved`; the input stays finite and within bounds.
            #[test]
            fn absurd_states_are_out_of_envelope_not_solved() {
                let r = window("circular", 0.0);
                let mut cases = Vec::new();
                for p in [1e6, 1e12, 1e30] {
                    let mut x0 = [0.0; NX];
                    x0[0] = p;
                    cases.push((x0, r));
                }
                let mut fast = [0.0; NX];
                fast[6] = 1e3;
                cases.push((fast, r));
                let mut far_r = r;
                far_r[N][2] = 1e7;
                cases.push(([0.0; NX], far_r));
                for (x0, r) in cases {
                    let mut mpc = Mpc::new();
                    let s = mpc.solve(&x0, &r);
                    assert_eq!(s.status, Status::OutOfEnvelope, "x0 {:?}", &x0[..7]);
                    for i in 0..NU {
                        assert!(s.u0[i].is_finite() && s.u0[i] >= $krate::U_MIN[i] && s.u0[i] <= $krate::U_MAX[i]);
                    }
                }
                // Inside the envelope the same solver says Solved (or a usable status).
                let mut mpc = Mpc::new();
                let mut x0 = [0.0; NX];
                x0[..3].copy_from_slice(&[3.0, 3.0, 5.0]);
                let s = mpc.solve(&x0, &r);
                assert_ne!(s.status, Status::OutOfEnvelope);
            }
        }
    };
}

/// A crate generated from a model file with an `envelope` carries it as ENVELOPE_LO/HI (the
/// generic bounds elsewhere) and flags x₀ and references just beyond it, not those just inside.
macro_rules! declared_envelope {
    ($name:ident, $krate:ident, $model:literal) => {
        #[test]
        fn $name() {
            use $krate::{Mpc, Status, ENVELOPE_HI, ENVELOPE_LO, N, NX};
            let model = shipped_model($model);
            let declared = model
                .envelope
                .clone()
                .expect("the shipped model declares an envelope");
            let generic = uavgen::discretize::Envelope::default().plausibility_bounds(&model.states);
            for i in 0..NX {
                let (lo, hi) = declared
                    .get(&model.states[i])
                    .unwrap_or((-generic[i], generic[i]));
                assert_eq!((ENVELOPE_LO[i], ENVELOPE_HI[i]), (lo, hi), "{}", model.states[i]);
            }
            let hover = {
                let mut x = [0.0; NX];
                x[..3].copy_from_slice(&[3.0, 3.0, 5.0]);
                x
            };
            let mut r = [[0.0; NX]; N + 1];
            for row in r.iter_mut() {
                row[..3].copy_from_slice(&[3.0, 3.0, 5.0]);
            }
            let status = |x0: &[f64; NX], r: &[[f64; NX]; N + 1]| {
                let mut mpc = Mpc::new();
                mpc.initialize(&hover, &[0.0; $krate::NU]);
                let s = mpc.solve(x0, r);
                for i in 0..$krate::NU {
                    assert!(s.u0[i].is_finite() && s.u0[i] >= $krate::U_MIN[i] && s.u0[i] <= $krate::U_MAX[i]);
                }
                s.status
            };
            assert_eq!(status(&hover, &r), Status::Solved);
            for (state, lo, hi) in &declared.bounds {
                let i = model.states.iter().position(|s| s == state).unwrap();
                // 1 % of the range beyond either end: flagged; 1 % inside both ends: solved.
                let step = 0.01 * (hi - lo);
                for (v, expected) in [
                    (hi + step, Status::OutOfEnvelope),
                    (lo - step, Status::OutOfEnvelope),
                    (hi - step, Status::Solved),
                    (lo + step, Status::Solved),
                ] {
                    let mut x0 = hover;
                    x0[i] = v;
                    assert_eq!(status(&x0, &r), expected, "x0 {state} = {v}");
                }
                // A reference row beyond the envelope is flagged too.
                let mut far = r;
                far[N][i] = hi + step;
                assert_eq!(
                    status(&hover, &far),
                    Status::OutOfEnvelope,
                    "reference {state} = {}",
                    hi + step
                );
            }
        }
    };
}

declared_envelope!(sindy_m100_declared_envelope, sindy_m100, "sindy_m100");
declared_envelope!(pd_m100_declared_envelope, pd_m100, "pd_m100");
declared_envelope!(sindy_m100_riccati_declared_envelope, sindy_m100_riccati, "sindy_m100");

comparisons!(sindy, sindy_m100, "sindy_m100", hovers: true);
comparisons!(pd_hover_model, pd_hover, "pd_hover", hovers: true);
comparisons!(pd_m100_model, pd_m100, "pd_m100", hovers: true);
// The paper's ξ do not hold the aircraft up: with saturated inputs the large-residual
// Gauss-Newton iteration cycles (in both solvers alike), so only agreement is checked.
comparisons!(pd_paper_model, pd_paper, "pd_paper", hovers: false);
// The stage-wise solver (`--qp riccati`) on the same model and problem.
comparisons!(sindy_riccati, sindy_m100_riccati, "sindy_m100", hovers: true);

/// The stage-wise crate is generated with the default options, so the comparisons above carry the
/// input-rate term (its u₋₁ moved by `shift` in the closed loops).
#[test]
fn default_rate_weight_in_the_riccati_crate() {
    let defaults = MpcOptions::defaults(&shipped_model("sindy_m100"));
    assert_eq!(sindy_m100_riccati::R_DELTA.to_vec(), defaults.r_delta);
    assert!(sindy_m100_riccati::R_DELTA.iter().any(|&s| s != 0.0));
    assert_eq!(sindy_m100_riccati::R_DELTA, sindy_m100::R_DELTA);
}

macro_rules! f32_comparison {
    ($name:ident, $krate:ident) => {
        #[test]
        fn $name() {
            use $krate::{Mpc, DT, N, NU, NX, SUBSTEPS};
            let mut reference_solver = generic(
                "pd_hover",
                f64::from(DT),
                SUBSTEPS,
                N,
                &$krate::R_DELTA.map(f64::from),
            );
            let mut worst: f64 = 0.0;
            for (instance, (x, _)) in envelope_points(200, 9).into_iter().enumerate() {
                let mut x0 = [0.0f32; NX];
                for i in 0..NX {
                    x0[i] = x[i] as f32;
                }
                let mut reference = [[0.0f32; NX]; N + 1];
                for (k, row) in reference.iter_mut().enumerate() {
                    let p = trajectory("circular", k as f64 * f64::from(DT) + instance as f64);
                    for i in 0..3 {
                        row[i] = p[i] as f32;
                    }
                }
                let mut mpc = Mpc::new();
                mpc.solve(&x0, &reference);
                reference_solver.set_guess(vec![vec![0.0; NX]; N + 1], vec![vec![0.0; NU]; N]);
                let x0d: Vec<f64> = x0.iter().map(|&v| f64::from(v)).collect();
                let rd: Vec<Vec<f64>> = reference
                    .iter()
                    .map(|r| r.iter().map(|&v| f64::from(v)).collect())
                    .collect();
                reference_solver.rti_step(&x0d, &rd).unwrap();
                for k in 0..N {
                    for i in 0..NU {
                        let d = (f64::from(mpc.planned_inputs()[k][i]) - reference_solver.planned_inputs()[k][i]).abs();
                        worst = worst.max(d / INPUT_BOUNDS[i]);
                    }
                }
            }
            eprintln!(
                "{}: worst planned-input difference (relative to the bound) {worst:.1e}",
                stringify!($krate)
            );
            assert!(worst <= 1e-3, "f32 plans differ by {worst:e}");
        }
    };
}

f32_comparison!(f32_solver_tracks_the_generic_f64_solver, pd_hover_f32);
