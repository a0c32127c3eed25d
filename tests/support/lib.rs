//! Shared helpers for the cross-crate tests: shipped models, random points
//! in the operating envelope, tolerances.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::path::PathBuf;
use uavgen::{Model, ModelIr};

/// The repository root (parent of this crate).
pub fn repo_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ has a parent")
        .to_owned()
}

/// Load `models/<name>.json`.
pub fn shipped_model(name: &str) -> Model {
    let path = repo_root().join("models").join(format!("{name}.json"));
    uavgen::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// Load a shipped model and lower it to the symbolic IR.
pub fn shipped_ir(name: &str) -> ModelIr {
    ModelIr::new(&shipped_model(name))
}

/// Bounds of the test envelope: positions ±10 m, roll/pitch ±0.6 rad, yaw ±π,
/// velocities ±5 m/s, Euler rates ±3 rad/s; inputs within the MPC's bounds.
pub const STATE_BOUNDS: [f64; 12] = [10.0, 10.0, 10.0, 0.6, 0.6, PI, 5.0, 5.0, 5.0, 3.0, 3.0, 3.0];
pub const INPUT_BOUNDS: [f64; 4] = [5.0, 0.611, 0.611, 5.0 * PI / 6.0];

/// `count` deterministic random (state, input) pairs in the envelope.
pub fn envelope_points(count: usize, seed: u64) -> Vec<([f64; 12], [f64; 4])> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let x = STATE_BOUNDS.map(|b| rng.gen_range(-b..=b));
            let u = INPUT_BOUNDS.map(|b| rng.gen_range(-b..=b));
            (x, u)
        })
        .collect()
}

/// |a − b| ≤ tol · max(|a|, |b|, 1): relative error with a unit floor, so
/// entries near zero are compared absolutely at the same tolerance.
pub fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * a.abs().max(b.abs()).max(1.0)
}

/// Largest scaled error of two equally long slices (see [`close`]).
pub fn max_scaled_error(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs() / x.abs().max(y.abs()).max(1.0))
        .fold(0.0, f64::max)
}
