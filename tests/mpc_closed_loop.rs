//! Closed loops of the generated MPC with the model itself as plant.

use std::time::Instant;

fn circle(t: f64) -> [f64; 3] {
    [5.0 * t.cos(), 5.0 * t.sin(), 6.0]
}

macro_rules! closed_loop {
    ($krate:ident) => {{
        use $krate::*;
        let mut mpc = Mpc::new();
        let mut x = [0.0 as Real; NX];
        x[0] = 3.0;
        x[1] = 3.0;
        x[2] = 5.0;
        let mut worst = std::time::Duration::ZERO;
        let mut total = std::time::Duration::ZERO;
        let mut err2 = 0.0;
        let mut max_iter = 0;
        let steps = 900;
        for step in 0..steps {
            let t = step as f64 * DT as f64;
            let mut reference = [[0.0 as Real; NX]; N + 1];
            for (k, r) in reference.iter_mut().enumerate() {
                let p = circle(t + k as f64 * DT as f64);
                r[0] = p[0] as Real;
                r[1] = p[1] as Real;
                r[2] = p[2] as Real;
            }
            let start = Instant::now();
            let s = mpc.solve(&x, &reference);
            let el = start.elapsed();
            worst = worst.max(el);
            total += el;
            max_iter = max_iter.max(s.qp_iterations);
            assert!(matches!(s.status, Status::Solved), "step {step}: {:?}", s.status);
            for i in 0..NU {
                assert!(s.u0[i] >= U_MIN[i] && s.u0[i] <= U_MAX[i]);
            }
            x = discrete_dynamics(&x, &s.u0);
            mpc.shift();
            if step >= 300 {
                for i in 0..3 {
                    let e = (x[i] - reference[1][i]) as f64;
                    err2 += e * e;
                }
            }
        }
        let rmse = (err2 / (3.0 * (steps - 300) as f64)).sqrt();
        eprintln!(
            "{}: tracking RMSE {rmse:.3} m, mean {:?}, worst {:?}, max QP iterations {max_iter}",
            stringify!($krate),
            total / steps as u32,
            worst
        );
        rmse
    }};
}

#[test]
fn sindy_tracks_the_circle() {
    let rmse = closed_loop!(sindy_m100);
    assert!(rmse < 1.0);
}

#[test]
fn pd_m100_tracks_the_circle() {
    let rmse = closed_loop!(pd_m100);
    assert!(rmse < 1.0);
}

#[test]
fn pd_hover_tracks_the_circle() {
    let rmse = closed_loop!(pd_hover);
    assert!(rmse < 1.0);
}

#[test]
fn sindy_riccati_tracks_the_circle() {
    let rmse = closed_loop!(sindy_m100_riccati);
    assert!(rmse < 1.0);
}
