//! The structure-specialised kernels of the generated crates (`kernels.rs`, emitted by
//! generator/src/codegen/kernels.rs) against the dense reference loops of
//! templates/src/kernels.rs, on random values with the crate's patterns; the patterns against
//! the generator's symbolic propagation and against the crate's own linearisation.

use proptest::prelude::*;
use uavgen::codegen::kernels::Structure;
use uavgen::MpcOptions;
use uavgen_tests::{envelope_points, shipped_ir, shipped_model};

macro_rules! structure_tests {
    ($name:ident, $krate:ident, $model:literal, $substeps:expr) => {
        mod $name {
            use super::*;
            use $krate::kernels::*;
            use $krate::{Real, N, NU, NV, NX, Q, Q_TERMINAL};

            type A = [[Real; NX]; NX];
            type B = [[Real; NU]; NX];
            type E = [[Real; NX]; NU];

            /// A matrix with the pattern's shape, `values` where it is true and 0 elsewhere.
            fn fill<const R: usize, const C: usize>(pattern: &[[bool; C]; R], values: &[f64]) -> [[Real; C]; R] {
                let mut out = [[0.0; C]; R];
                for r in 0..R {
                    for c in 0..C {
                        if pattern[r][c] {
                            out[r][c] = values[(r * C + c) % values.len()] as Real;
                        }
                    }
                }
                out
            }

            // The dense loops of templates/src/kernels.rs.
            fn dense_bt_p(b: &B, p: &A) -> E {
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
            fn dense_e_b(e: &E, b: &B) -> [[Real; NU]; NU] {
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
            fn dense_e_a(e: &E, a: &A) -> E {
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
            fn dense_at_p_a(p: &A, a: &A) -> A {
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

            fn generator_structure() -> Structure {
                let model = shipped_model($model);
                let mpc = MpcOptions::defaults(&model);
                Structure::from_ir(&shipped_ir($model), $substeps, &mpc.q, &mpc.q_terminal)
            }

            fn to_vec<const R: usize, const C: usize>(p: &[[bool; C]; R]) -> Vec<Vec<bool>> {
                p.iter().map(|r| r.to_vec()).collect()
            }

            #[test]
            fn patterns_are_the_generators() {
                let s = generator_structure();
                assert_eq!(s.a, to_vec(&A_PATTERN));
                assert_eq!(s.b, to_vec(&B_PATTERN));
                assert_eq!(s.p, to_vec(&P_PATTERN));
                assert_eq!(s.e, to_vec(&E_PATTERN));
            }

            #[test]
            fn linearisation_is_zero_outside_the_patterns() {
                for (x, u) in envelope_points(200, 11) {
                    let x: [Real; NX] = core::array::from_fn(|i| x[i] as Real);
                    let u: [Real; NU] = core::array::from_fn(|i| u[i] as Real);
                    let (a, b) = $krate::discrete_jacobians(&x, &u);
                    for r in 0..NX {
                        for c in 0..NX {
                            assert!(A_PATTERN[r][c] || a[r][c] == 0.0, "A[{r}][{c}] = {}", a[r][c]);
                        }
                        for c in 0..NU {
                            assert!(B_PATTERN[r][c] || b[r][c] == 0.0, "B[{r}][{c}] = {}", b[r][c]);
                        }
                    }
                }
            }

            proptest! {
                #![proptest_config(ProptestConfig::with_cases(200))]

                #[test]
                fn kernels_equal_the_dense_loops(
                    values in proptest::collection::vec(-2.0f64..2.0, 144),
                    more in proptest::collection::vec(-2.0f64..2.0, 144),
                    x in proptest::array::uniform12(-2.0f64..2.0),
                    v in proptest::array::uniform4(-2.0f64..2.0),
                ) {
                    let a: A = fill(&A_PATTERN, &values);
                    let b: B = fill(&B_PATTERN, &more);
                    let p: A = fill(&P_PATTERN, &more);
                    let e: E = fill(&E_PATTERN, &values);
                    let x: [Real; NX] = core::array::from_fn(|i| x[i] as Real);
                    let v: [Real; NU] = core::array::from_fn(|i| v[i] as Real);
                    // Same summation order: equal, not just close.
                    prop_assert_eq!(bt_p(&b, &p), dense_bt_p(&b, &p));
                    prop_assert_eq!(e_b(&e, &b), dense_e_b(&e, &b));
                    prop_assert_eq!(e_a(&e, &a), dense_e_a(&e, &a));
                    prop_assert_eq!(at_p_a(&p, &a), dense_at_p_a(&p, &a));
                    // The chains of every stage at once: chain i is E scaled by (i + 1), lanes
                    // before `from` are left alone (chains_a) and H gets E B both ways (chains_b).
                    let from = 3;
                    let mut w: Chains = [[[0.0; N]; NU]; NX];
                    let chain = |i: usize| -> E {
                        let mut ei = e;
                        for row in ei.iter_mut() {
                            for v in row.iter_mut() {
                                *v *= (i + 1) as Real;
                            }
                        }
                        ei
                    };
                    for i in 0..N {
                        let ei = chain(i);
                        for k in 0..NX {
                            for r in 0..NU {
                                w[k][r][i] = ei[r][k];
                            }
                        }
                    }
                    let mut out: Chains = w;
                    chains_a(&mut out, &a, from, &mut [[0.0; N]; SAVED_ROWS]);
                    let mut h = [[0.0; NV]; NV];
                    let j = 1;
                    chains_b(&w, &b, j, from, &mut h);
                    for i in 0..N {
                        let (ea, eb) = (dense_e_a(&chain(i), &a), dense_e_b(&chain(i), &b));
                        for r in 0..NU {
                            for c in 0..NX {
                                if i < from {
                                    prop_assert_eq!(out[c][r][i], w[c][r][i]);
                                } else if E_PATTERN[r][c] {
                                    prop_assert_eq!(out[c][r][i], ea[r][c]);
                                }
                            }
                            for c in 0..NU {
                                let expected = if i < from { 0.0 } else { eb[r][c] };
                                prop_assert_eq!(h[i * NU + r][j * NU + c], expected);
                                prop_assert_eq!(h[j * NU + c][i * NU + r], expected);
                            }
                        }
                    }
                    let mut ax = x;
                    let mut bv = x;
                    let mut atx = [0.0; NX];
                    let mut btx = v;
                    for i in 0..NX {
                        for j in 0..NX {
                            ax[i] += a[i][j] * x[j];
                            atx[i] += a[j][i] * x[j];
                        }
                        for j in 0..NU {
                            bv[i] += b[i][j] * v[j];
                        }
                    }
                    for r in 0..NU {
                        for k in 0..NX {
                            btx[r] += b[k][r] * x[k];
                        }
                    }
                    prop_assert_eq!(a_x_add(&a, &x, &x), ax);
                    prop_assert_eq!(b_x_add(&b, &v, &x), bv);
                    prop_assert_eq!(at_x(&a, &x), atx);
                    prop_assert_eq!(bt_x_add(&b, &x, &v), btx);
                    // The patterns are closed under the condensing's products: P ↦ Q + Aᵀ P A
                    // and E ↦ E A, E = Bᵀ P stay within them.
                    let mut next = dense_at_p_a(&p, &a);
                    for r in 0..NX {
                        next[r][r] += Q[r] + Q_TERMINAL[r];
                    }
                    let chain = dense_e_a(&dense_bt_p(&b, &p), &a);
                    for r in 0..NX {
                        for c in 0..NX {
                            prop_assert!(P_PATTERN[r][c] || next[r][c] == 0.0);
                        }
                    }
                    for r in 0..NU {
                        for c in 0..NX {
                            prop_assert!(E_PATTERN[r][c] || chain[r][c] == 0.0);
                        }
                    }
                }
            }
        }
    };
}

structure_tests!(sindy_m100_kernels, sindy_m100, "sindy_m100", 1);
structure_tests!(pd_m100_kernels, pd_m100, "pd_m100", 1);
structure_tests!(pd_paper_kernels, pd_paper, "pd_paper", 3);
structure_tests!(pd_hover_kernels, pd_hover, "pd_hover", 1);
structure_tests!(pd_hover_f32_kernels, pd_hover_f32, "pd_hover", 1);
