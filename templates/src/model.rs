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

/// Structural non-zeros of every sensitivity S = ∂x/∂(x₀, u) of the RK4 recursion (the generator
/// emits the model's; all true here: the dense reference).
pub const S_PATTERN: [[bool; NZ]; NX] = [[true; NZ]; NX];

/// A sensitivity-shaped matrix (NX × NZ): S = ∂x/∂(x₀, u), a stage's S + a D, or the RK4 sum
/// D1 + 2 D2 + 2 D3 of a substep.
pub type Sens = [[Real; NZ]; NX];

/// Number of values [`continuous_derivatives`] writes: here every entry of [∂f/∂x ∂f/∂u], row by
/// row (the generator stores only the structural non-zeros that are not constants).
pub const NJ: usize = NX * NZ;

/// f(x, u), writing the values of [∂f/∂x ∂f/∂u] the stage kernels below need into `jv`.
pub fn continuous_derivatives(x: &[Real; NX], u: &[Real; NU], jv: &mut [Real; NJ]) -> [Real; NX] {
    let (fx, fu) = continuous_jacobians(x, u);
    for i in 0..NX {
        jv[i * NZ..i * NZ + NX].copy_from_slice(&fx[i]);
        jv[i * NZ + NX..(i + 1) * NZ].copy_from_slice(&fu[i]);
    }
    continuous_dynamics(x, u)
}

/// ∂fᵢ/∂zₖ (z = (x, u)) from `jv`.
#[inline(always)]
fn jac(jv: &[Real; NJ], i: usize, k: usize) -> Real {
    jv[i * NZ + k]
}

/// Entry (i, j) of D = ∂f/∂x · Y + ∂f/∂u · [0 I].
#[inline(always)]
fn product(jv: &[Real; NJ], y: &Sens, i: usize, j: usize) -> Real {
    let mut d = 0.0;
    for k in 0..NX {
        d += jac(jv, i, k) * y[k][j];
    }
    if j >= NX {
        d += jac(jv, i, j);
    }
    d
}

/// [I 0]
fn identity() -> Sens {
    let mut s = [[0.0; NZ]; NX];
    for (i, row) in s.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    s
}

// The RK4 stages of one substep (docs/discretisation.md): with D = ∂f/∂x · Y + ∂f/∂u · [0 I] at
// the stage's Y, stage 1 (Y = S) sets ACC = D and writes the next stage's Y = S + a D, stages 2
// and 3 add 2 D to ACC and write S + a D, stage 4 updates S += c (ACC + D). The `_at_identity`
// kernels are the same for S = [I 0] (the first substep of a sample, S not read); the generator
// specialises each of the eight to the structural non-zeros the recursion has there and emits
// straight-line code. Every kernel reads its inputs only where the kernel before wrote them.

/// Stage 1: ACC = D, Y = S + a D with D at Y = S.
pub fn sensitivity_stage1(jv: &[Real; NJ], s: &Sens, a: Real, acc: &mut Sens, y: &mut Sens) {
    for i in 0..NX {
        for j in 0..NZ {
            let d = product(jv, s, i, j);
            acc[i][j] = d;
            y[i][j] = s[i][j] + a * d;
        }
    }
}

/// Stage 2 or 3: ACC += 2 D, Y⁺ = S + a D with D at Y.
pub fn sensitivity_stage2(jv: &[Real; NJ], y: &Sens, s: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
    for i in 0..NX {
        for j in 0..NZ {
            let d = product(jv, y, i, j);
            acc[i][j] += 2.0 * d;
            y_next[i][j] = s[i][j] + a * d;
        }
    }
}

/// Stage 3 (the generator's input pattern differs from stage 2's).
pub fn sensitivity_stage3(jv: &[Real; NJ], y: &Sens, s: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
    sensitivity_stage2(jv, y, s, a, acc, y_next);
}

/// Stage 4: S += c (ACC + D) with D at Y.
pub fn sensitivity_stage4(jv: &[Real; NJ], y: &Sens, c: Real, acc: &Sens, s: &mut Sens) {
    for i in 0..NX {
        for j in 0..NZ {
            s[i][j] += c * (acc[i][j] + product(jv, y, i, j));
        }
    }
}

/// [`sensitivity_stage1`] at S = [I 0]: D = [∂f/∂x ∂f/∂u], no products.
pub fn sensitivity_stage1_at_identity(jv: &[Real; NJ], a: Real, acc: &mut Sens, y: &mut Sens) {
    let s = identity();
    for i in 0..NX {
        for j in 0..NZ {
            let d = jac(jv, i, j);
            acc[i][j] = d;
            y[i][j] = s[i][j] + a * d;
        }
    }
}

/// [`sensitivity_stage2`] at S = [I 0].
pub fn sensitivity_stage2_at_identity(jv: &[Real; NJ], y: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
    sensitivity_stage2(jv, y, &identity(), a, acc, y_next);
}

/// [`sensitivity_stage3`] at S = [I 0].
pub fn sensitivity_stage3_at_identity(jv: &[Real; NJ], y: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
    sensitivity_stage3(jv, y, &identity(), a, acc, y_next);
}

/// [`sensitivity_stage4`] at S = [I 0]: writes S = [I 0] + c (ACC + D).
pub fn sensitivity_stage4_at_identity(jv: &[Real; NJ], y: &Sens, c: Real, acc: &Sens, s: &mut Sens) {
    *s = identity();
    sensitivity_stage4(jv, y, c, acc, s);
}
