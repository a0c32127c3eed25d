//! Example model for the template's own tests (the generator emits its own
//! `model` module with these three functions).
//!
//! Damped oscillator: ẋ₀ = x₁, ẋ₁ = −K x₀ − C x₁ + B u.

use crate::{Real, NU, NX, NZ};

const K: Real = 4.0;
const C: Real = 0.5;
const B: Real = 2.0;

/// ẋ = f(x, u)
pub fn continuous_dynamics(x: &[Real; NX], u: &[Real; NU]) -> [Real; NX] {
    [x[1], -K * x[0] - C * x[1] + B * u[0]]
}

/// (∂f/∂x, ∂f/∂u)
pub fn continuous_jacobians(_x: &[Real; NX], _u: &[Real; NU]) -> ([[Real; NX]; NX], [[Real; NU]; NX]) {
    ([[0.0, 1.0], [-K, -C]], [[0.0], [B]])
}

/// (f(x, u), ∂f/∂x · S + ∂f/∂u · [0 I]) for a sensitivity S = ∂x/∂(x₀, u).
pub fn continuous_sensitivity(x: &[Real; NX], u: &[Real; NU], s: &[[Real; NZ]; NX]) -> ([Real; NX], [[Real; NZ]; NX]) {
    let f = continuous_dynamics(x, u);
    let mut ds = [[0.0; NZ]; NX];
    ds[0] = s[1];
    for j in 0..NZ {
        ds[1][j] = -K * s[0][j] - C * s[1][j];
    }
    ds[1][NX] += B;
    (f, ds)
}
