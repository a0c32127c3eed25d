//! Products with the stage matrices Aₖ, Bₖ used by the condensing and the feedback of `mpc.rs`.
//!
//! These are the dense reference kernels. The generator replaces this module by one emitted for
//! the model (generator/src/codegen/kernels.rs): the same functions as straight-line code over
//! the structural non-zeros of Aₖ, Bₖ and of the products the condensing forms (`A_PATTERN`,
//! `B_PATTERN`, `P_PATTERN`, `E_PATTERN`; here all true), so a multiplication by a structural
//! zero is never executed. Each entry is summed in the order of the loops below (ascending inner
//! index), so for inputs that are zero outside the patterns the emitted kernels return the same
//! numbers as these.

use crate::{Real, N, NU, NV, NX};

/// Structural non-zeros of Aₖ = ∂F/∂x (all true: dense reference).
pub const A_PATTERN: [[bool; NX]; NX] = [[true; NX]; NX];
/// Structural non-zeros of Bₖ = ∂F/∂u.
pub const B_PATTERN: [[bool; NU]; NX] = [[true; NU]; NX];
/// Structural non-zeros of every Pᵢ of the condensing recursion (a superset closed under
/// P ↦ Q + Aᵀ P A).
pub const P_PATTERN: [[bool; NX]; NX] = [[true; NX]; NX];
/// Structural non-zeros of every chain E = Bᵢᵀ Pᵢ₊₁ Aᵢ ⋯ A_{j+1} (closed under E ↦ E A).
pub const E_PATTERN: [[bool; NX]; NU] = [[true; NX]; NU];

/// Component of each input in the condensed Hessian's coupling graph: H has exact zeros between
/// the inputs (of any stages) of different components. Numbered largest component first.
pub const INPUT_COMPONENT: [u8; NU] = [0; NU];

/// Bᵀ P (P with `P_PATTERN`).
pub fn bt_p(b: &[[Real; NU]; NX], p: &[[Real; NX]; NX]) -> [[Real; NX]; NU] {
    let mut m = [[0.0; NX]; NU];
    for r in 0..NU {
        for c in 0..NX {
            let mut s = 0.0;
            for k in 0..NX {
                s += b[k][r] * p[k][c];
            }
            m[r][c] = s;
        }
    }
    m
}

/// E B (E with `E_PATTERN`).
pub fn e_b(e: &[[Real; NX]; NU], b: &[[Real; NU]; NX]) -> [[Real; NU]; NU] {
    let mut out = [[0.0; NU]; NU];
    for r in 0..NU {
        for c in 0..NU {
            let mut s = 0.0;
            for k in 0..NX {
                s += e[r][k] * b[k][c];
            }
            out[r][c] = s;
        }
    }
    out
}

/// E A (E with `E_PATTERN`).
pub fn e_a(e: &[[Real; NX]; NU], a: &[[Real; NX]; NX]) -> [[Real; NX]; NU] {
    let mut out = [[0.0; NX]; NU];
    for r in 0..NU {
        for c in 0..NX {
            let mut s = 0.0;
            for k in 0..NX {
                s += e[r][k] * a[k][c];
            }
            out[r][c] = s;
        }
    }
    out
}

/// Every chain of the condensing at once: `w[k][r][i]` is entry (r, k) of the chain Eᵢ (NU × NX)
/// of stage i. The stages i are the innermost, contiguous index, so each term of E A or E B is one
/// product over all the chains the condensing carries, a loop the compiler vectorises.
pub type Chains = [[[Real; N]; NU]; NX];

/// Rows (c, r) of the chains that `chains_a` overwrites while a later row still reads them (the
/// emitted kernel saves only those; the dense one all NX·NU).
pub const SAVED_ROWS: usize = NX * NU;

/// The workspace of `chains_a`.
pub type SavedRows = [[Real; N]; SAVED_ROWS];

/// Eᵢ ← Eᵢ A in place for the chains i in `from..N`: `w[c][r][i]` = Σₖ `w[k][r][i]` a[k][c] of
/// the old `w` (E with `E_PATTERN`; entry by entry the sum of [`e_a`]); `saved` is scratch.
pub fn chains_a(w: &mut Chains, a: &[[Real; NX]; NX], from: usize, saved: &mut SavedRows) {
    for k in 0..NX {
        for r in 0..NU {
            saved[k * NU + r] = w[k][r];
        }
    }
    for c in 0..NX {
        for r in 0..NU {
            for i in from..N {
                let mut s = 0.0;
                for k in 0..NX {
                    s += saved[k * NU + r][i] * a[k][c];
                }
                w[c][r][i] = s;
            }
        }
    }
}

/// H_ij = Eᵢ B_j for the chains i in `from..N` into the condensed Hessian, and H_ji = H_ijᵀ:
/// H[i NU + r][j NU + c] = H[j NU + c][i NU + r] = Σₖ `w[k][r][i]` b[k][c] (entry by entry the
/// sum of [`e_b`]).
pub fn chains_b(w: &Chains, b: &[[Real; NU]; NX], j: usize, from: usize, h: &mut [[Real; NV]; NV]) {
    let j = j.min(N - 1);
    for c in 0..NU {
        for r in 0..NU {
            for i in from..N {
                let mut s = 0.0;
                for k in 0..NX {
                    s += w[k][r][i] * b[k][c];
                }
                h[i * NU + r][j * NU + c] = s;
                h[j * NU + c][i * NU + r] = s;
            }
        }
    }
}

/// Aᵀ (P A) (P with `P_PATTERN`): its upper triangle, mirrored (the result is exactly
/// symmetric).
pub fn at_p_a(p: &[[Real; NX]; NX], a: &[[Real; NX]; NX]) -> [[Real; NX]; NX] {
    let mut t = [[0.0; NX]; NX];
    for r in 0..NX {
        for c in 0..NX {
            let mut s = 0.0;
            for k in 0..NX {
                s += p[r][k] * a[k][c];
            }
            t[r][c] = s;
        }
    }
    let mut out = [[0.0; NX]; NX];
    for r in 0..NX {
        for c in r..NX {
            let mut s = 0.0;
            for k in 0..NX {
                s += a[k][r] * t[k][c];
            }
            out[r][c] = s;
            out[c][r] = s;
        }
    }
    out
}

/// y + A x
pub fn a_x_add(a: &[[Real; NX]; NX], x: &[Real; NX], y: &[Real; NX]) -> [Real; NX] {
    let mut out = *y;
    for i in 0..NX {
        for j in 0..NX {
            out[i] += a[i][j] * x[j];
        }
    }
    out
}

/// y + B v
pub fn b_x_add(b: &[[Real; NU]; NX], v: &[Real; NU], y: &[Real; NX]) -> [Real; NX] {
    let mut out = *y;
    for i in 0..NX {
        for j in 0..NU {
            out[i] += b[i][j] * v[j];
        }
    }
    out
}

/// y + Bᵀ p
pub fn bt_x_add(b: &[[Real; NU]; NX], p: &[Real; NX], y: &[Real; NU]) -> [Real; NU] {
    let mut out = *y;
    for r in 0..NU {
        for k in 0..NX {
            out[r] += b[k][r] * p[k];
        }
    }
    out
}

/// Aᵀ p
pub fn at_x(a: &[[Real; NX]; NX], p: &[Real; NX]) -> [Real; NX] {
    let mut out = [0.0; NX];
    for i in 0..NX {
        for k in 0..NX {
            out[i] += a[k][i] * p[k];
        }
    }
    out
}
