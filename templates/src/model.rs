//! Example model for the template's own tests (the generator emits its own
//! `model` module with these functions).
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

/// [`continuous_sensitivity`] at S = [I 0] (the first stage of a sample): (f(x, u), [∂f/∂x ∂f/∂u]).
pub fn continuous_sensitivity_at_identity(x: &[Real; NX], u: &[Real; NU]) -> ([Real; NX], [[Real; NZ]; NX]) {
    let (fx, fu) = continuous_jacobians(x, u);
    let mut ds = [[0.0; NZ]; NX];
    for i in 0..NX {
        ds[i][..NX].copy_from_slice(&fx[i]);
        ds[i][NX..].copy_from_slice(&fu[i]);
    }
    (continuous_dynamics(x, u), ds)
}

/// Structural non-zeros of every sensitivity S = ∂x/∂(x₀, u) of the RK4 recursion (the generator
/// emits the model's; all true here: the dense reference).
pub const S_PATTERN: [[bool; NZ]; NX] = [[true; NZ]; NX];

/// Y = S + a D (over `S_PATTERN`; the generator emits straight-line code over the model's).
#[inline(always)]
pub fn sensitivity_axpy(s: &[[Real; NZ]; NX], a: Real, d: &[[Real; NZ]; NX]) -> [[Real; NZ]; NX] {
    let mut y = *s;
    for (yr, dr) in y.iter_mut().zip(d) {
        for (yi, di) in yr.iter_mut().zip(dr) {
            *yi += a * di;
        }
    }
    y
}

/// S += c (D1 + 2 D2 + 2 D3 + D4) (over `S_PATTERN`).
#[inline(always)]
pub fn sensitivity_step(
    s: &mut [[Real; NZ]; NX],
    c: Real,
    d1: &[[Real; NZ]; NX],
    d2: &[[Real; NZ]; NX],
    d3: &[[Real; NZ]; NX],
    d4: &[[Real; NZ]; NX],
) {
    for i in 0..NX {
        for j in 0..NZ {
            s[i][j] += c * (d1[i][j] + 2.0 * d2[i][j] + 2.0 * d3[i][j] + d4[i][j]);
        }
    }
}
