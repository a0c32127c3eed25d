//! Emits `kernels.rs`: the stage-matrix products of the condensing and the feedback
//! (templates/src/kernels.rs, whose dense loops are the reference) as straight-line code over the
//! structural non-zeros the generator knows.
//!
//! The structure is propagated symbolically at generation time: the pattern of ∂f/∂x, ∂f/∂u (the
//! IR's structural zeros) through the RK4 sensitivity recursion of `rk4.rs` gives the patterns of
//! the discrete Aₖ, Bₖ; from those and the non-zero weights of Q, Q_N the closure of the
//! condensing recursion P ↦ Q + Aᵀ P A gives one pattern valid for every Pᵢ, and the closure of
//! E ↦ E A from Bᵀ P one for every chain E = Bᵢᵀ Pᵢ₊₁ Aᵢ ⋯ A_{j+1}. Every emitted entry is the sum
//! of the products whose factors are both structurally non-zero, in the order of the dense loops,
//! so a multiplication by a structural zero is never executed and the result equals the dense
//! kernel's for inputs that are zero outside the patterns. [`Structure::flops`] counts the
//! multiply-adds the emitted kernels perform (docs/benchmarks.md, "Structural zeros").

use crate::ir::ModelIr;
use proc_macro2::{Literal, TokenStream};
use quote::quote;

type Pattern = Vec<Vec<bool>>;

/// The structural patterns of one generated crate's stage matrices.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Structure {
    pub nx: usize,
    pub nu: usize,
    /// Aₖ (NX × NX).
    pub a: Pattern,
    /// Bₖ (NX × NU).
    pub b: Pattern,
    /// Every Pᵢ of the condensing (NX × NX).
    pub p: Pattern,
    /// Every chain E (NU × NX).
    pub e: Pattern,
    /// Every sensitivity S = ∂x/∂(x₀, u) of the RK4 recursion (NX × (NX + NU)); [A B] is its
    /// value at the end of a sample.
    pub s: Pattern,
}

fn zeros(rows: usize, cols: usize) -> Pattern {
    vec![vec![false; cols]; rows]
}

fn or(x: &Pattern, y: &Pattern) -> Pattern {
    x.iter()
        .zip(y)
        .map(|(a, b)| a.iter().zip(b).map(|(p, q)| *p || *q).collect())
        .collect()
}

/// Pattern of X Y.
fn mul(x: &Pattern, y: &Pattern) -> Pattern {
    let cols = y.first().map_or(0, Vec::len);
    x.iter()
        .map(|row| {
            (0..cols)
                .map(|c| row.iter().zip(y).any(|(&xk, yk)| xk && yk[c]))
                .collect()
        })
        .collect()
}

fn transpose(x: &Pattern, cols: usize) -> Pattern {
    (0..cols).map(|c| x.iter().map(|row| row[c]).collect()).collect()
}

fn count(x: &Pattern) -> usize {
    x.iter().flatten().filter(|v| **v).count()
}

/// Multiply-adds of one call of each emitted kernel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KernelFlops {
    pub bt_p: usize,
    pub e_b: usize,
    pub e_a: usize,
    pub at_p_a: usize,
    pub a_x: usize,
    pub b_x: usize,
    pub bt_x: usize,
    pub at_x: usize,
}

/// Multiply-adds per RTI step of the stage-matrix work (horizon N), by part.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepFlops {
    /// Condensing: N (Bᵀ P + M B) + N(N−1)/2 (E A + E B) + (N−1) Aᵀ P A, then G = ∂g/∂x₀ (N more
    /// E A) and the gradient g⁰ at the guess: free response N·A x, adjoint N·Bᵀ p + (N−1)·Aᵀ p.
    pub condensing: usize,
    /// Feedback: g = g⁰ + G z₀ (N·NU·NX) and the guess update N (A x + B v).
    pub feedback: usize,
    /// Cholesky factorisation of the condensed Hessian with every input free, Σ n³/6 over the
    /// components of [`Structure::input_components`] (n = N × the component's inputs): the upper
    /// bound of `prepare`'s factorisation of H_FF (fixed inputs make it smaller).
    pub cholesky: usize,
}

impl StepFlops {
    pub fn total(&self) -> usize {
        self.condensing + self.feedback + self.cholesky
    }
}

impl Structure {
    /// No structural zeros: the template's dense kernels.
    pub fn dense(nx: usize, nu: usize) -> Self {
        Self {
            nx,
            nu,
            a: vec![vec![true; nx]; nx],
            b: vec![vec![true; nu]; nx],
            p: vec![vec![true; nx]; nx],
            e: vec![vec![true; nx]; nu],
            s: vec![vec![true; nx + nu]; nx],
        }
    }

    /// From the patterns of ∂f/∂x (NX × NX) and ∂f/∂u (NX × NU), the RK4 substeps per sample and
    /// the weights diag(Q), diag(Q_N) (a zero weight is a structural zero).
    pub fn new(fx: &Pattern, fu: &Pattern, substeps: usize, q: &[f64], q_terminal: &[f64]) -> Self {
        let (nx, nu) = (fx.len(), fu.first().map_or(0, Vec::len));
        // S = ∂x/∂(x₀, u) from [I 0]; one stage dS = ∂f/∂x S + ∂f/∂u [0 I]; the stages see
        // S + a dS of the previous one, and S⁺ = S + h/6 (dS₁ + 2 dS₂ + 2 dS₃ + dS₄).
        let mut s = zeros(nx, nx + nu);
        for (i, row) in s.iter_mut().enumerate() {
            row[i] = true;
        }
        let stage = |s: &Pattern| -> Pattern {
            let mut d = mul(fx, s);
            for (row, fu_row) in d.iter_mut().zip(fu) {
                for (m, &nz) in fu_row.iter().enumerate() {
                    row[nx + m] |= nz;
                }
            }
            d
        };
        for _ in 0..substeps {
            let d1 = stage(&s);
            let d2 = stage(&or(&s, &d1));
            let d3 = stage(&or(&s, &d2));
            let d4 = stage(&or(&s, &d3));
            s = or(&or(&or(&s, &d1), &or(&d2, &d3)), &d4);
        }
        let a: Pattern = s.iter().map(|row| row[..nx].to_vec()).collect();
        let b: Pattern = s.iter().map(|row| row[nx..].to_vec()).collect();
        let mut weights = zeros(nx, nx);
        for i in 0..nx {
            weights[i][i] = q[i] != 0.0 || q_terminal[i] != 0.0;
        }
        let at = transpose(&a, nx);
        let mut p = weights.clone();
        loop {
            let next = or(&p, &mul(&at, &mul(&p, &a)));
            if next == p {
                break;
            }
            p = next;
        }
        let mut e = mul(&transpose(&b, nu), &p);
        loop {
            let next = or(&e, &mul(&e, &a));
            if next == e {
                break;
            }
            e = next;
        }
        Self { nx, nu, a, b, p, e, s }
    }

    /// The structure of a model's crate.
    pub fn from_ir(ir: &ModelIr, substeps: usize, q: &[f64], q_terminal: &[f64]) -> Self {
        let nz = |rows: &[Vec<crate::symbolic::Id>]| -> Pattern {
            rows.iter()
                .map(|r| r.iter().map(|&d| !ir.graph.is_zero(d)).collect())
                .collect()
        };
        Self::new(&nz(&ir.fx), &nz(&ir.fu), substeps, q, q_terminal)
    }

    /// Connected components of the inputs in the condensed Hessian: inputs r and c are coupled
    /// if some block H_ij (any stages) has a structurally non-zero entry (r, c), i.e. if
    /// (E B)[r][c] or (E B)[c][r] may be non-zero (H_ii = M Bᵢ + R, M within `E_PATTERN`). The
    /// QP variables of different components never couple, so the Cholesky factor of any subset
    /// of them has no entry between components. Component ids are numbered by first input.
    pub fn input_components(&self) -> Vec<usize> {
        let eb = mul(&self.e, &self.b);
        let nu = self.nu;
        let mut id: Vec<usize> = (0..nu).collect();
        // Union-find by repeated relabelling (NU is small).
        loop {
            let mut changed = false;
            for r in 0..nu {
                for c in 0..nu {
                    if (eb[r][c] || eb[c][r]) && id[r] != id[c] {
                        let (lo, hi) = (id[r].min(id[c]), id[r].max(id[c]));
                        for v in id.iter_mut() {
                            if *v == hi {
                                *v = lo;
                            }
                        }
                        changed = true;
                    }
                }
            }
            if !changed {
                break;
            }
        }
        // Renumber 0, 1, …: largest component first, then by first input (a stable sort).
        let mut roots: Vec<usize> = Vec::new();
        for v in &id {
            if !roots.contains(v) {
                roots.push(*v);
            }
        }
        roots.sort_by_key(|r| std::cmp::Reverse(id.iter().filter(|v| *v == r).count()));
        id.iter()
            .map(|v| roots.iter().position(|r| r == v).unwrap_or(0))
            .collect()
    }

    /// Structural non-zeros of (A, B).
    pub fn nonzeros(&self) -> (usize, usize) {
        (count(&self.a), count(&self.b))
    }

    /// The order in which `chains_a` overwrites the rows c of Eᵀ (those with a non-zero in some
    /// chain) and the rows it saves first because a row after them still reads their old value:
    /// greedily the row with the fewest such readers next (ties: the lowest index).
    pub fn chain_order(&self) -> (Vec<usize>, Vec<usize>) {
        let (nx, nu) = (self.nx, self.nu);
        // Row c of the new Eᵀ reads the old row k if a[k][c] and some lane r of both is non-zero.
        let reads = |c: usize, k: usize| self.a[k][c] && (0..nu).any(|r| self.e[r][k]);
        let mut remaining: Vec<usize> = (0..nx).filter(|&c| (0..nu).any(|r| self.e[r][c])).collect();
        let (mut order, mut saved) = (Vec::new(), Vec::new());
        while !remaining.is_empty() {
            let readers = |k: usize, remaining: &[usize]| remaining.iter().filter(|&&c| c != k && reads(c, k)).count();
            let Some(&next) = remaining.iter().min_by_key(|&&k| readers(k, &remaining)) else {
                break;
            };
            if readers(next, &remaining) > 0 {
                saved.push(next);
            }
            order.push(next);
            remaining.retain(|&k| k != next);
        }
        (order, saved)
    }

    /// Pattern of P A (the intermediate of `at_p_a`).
    fn pa(&self) -> Pattern {
        mul(&self.p, &self.a)
    }

    /// The terms (inner indices k) of every entry of each kernel, in summation order.
    fn terms(&self) -> Terms {
        let (nx, nu) = (self.nx, self.nu);
        let (a, b, p, e) = (&self.a, &self.b, &self.p, &self.e);
        let grid = |rows: usize, cols: usize, inner: usize, f: &dyn Fn(usize, usize, usize) -> bool| {
            (0..rows)
                .map(|r| {
                    (0..cols)
                        .map(|c| (0..inner).filter(|&k| f(r, c, k)).collect())
                        .collect()
                })
                .collect::<Vec<Vec<Vec<usize>>>>()
        };
        let pa = self.pa();
        Terms {
            bt_p: grid(nu, nx, nx, &|r, c, k| b[k][r] && p[k][c]),
            e_b: grid(nu, nu, nx, &|r, c, k| e[r][k] && b[k][c]),
            e_a: grid(nu, nx, nx, &|r, c, k| e[r][k] && a[k][c]),
            pa: grid(nx, nx, nx, &|r, c, k| p[r][k] && a[k][c]),
            // Aᵀ P A is symmetric: the upper triangle only (mirrored by `emit`).
            at_pa: grid(nx, nx, nx, &|r, c, k| c >= r && a[k][r] && pa[k][c]),
            a_x: grid(nx, 1, nx, &|i, _, j| a[i][j]),
            b_x: grid(nx, 1, nu, &|i, _, j| b[i][j]),
            bt_x: grid(nu, 1, nx, &|r, _, k| b[k][r]),
            at_x: grid(nx, 1, nx, &|i, _, k| a[k][i]),
            chains_a: grid(nx, nu, nx, &|c, r, k| a[k][c] && e[r][k]),
            chains_b: grid(nu, nu, nx, &|c, r, k| b[k][c] && e[r][k]),
        }
    }

    /// Multiply-adds of one call of each kernel.
    pub fn kernel_flops(&self) -> KernelFlops {
        let t = self.terms();
        let n = |g: &Vec<Vec<Vec<usize>>>| g.iter().flatten().map(Vec::len).sum::<usize>();
        KernelFlops {
            bt_p: n(&t.bt_p),
            e_b: n(&t.e_b),
            e_a: n(&t.e_a),
            at_p_a: n(&t.pa) + n(&t.at_pa),
            a_x: n(&t.a_x),
            b_x: n(&t.b_x),
            bt_x: n(&t.bt_x),
            at_x: n(&t.at_x),
        }
    }

    /// Multiply-adds per RTI step at horizon `n` (the loops of templates/src/mpc.rs).
    pub fn flops(&self, n: usize) -> StepFlops {
        let k = self.kernel_flops();
        let chains = n * n.saturating_sub(1) / 2;
        StepFlops {
            // … + the chains carried through A₀ (G = ∂g/∂x₀) + the gradient at the guess (free
            // response from z₀ = 0 and the adjoint sweep).
            condensing: n * (k.bt_p + k.e_b)
                + chains * (k.e_a + k.e_b)
                + n.saturating_sub(1) * k.at_p_a
                + n * k.e_a
                + n * k.a_x
                + n * k.bt_x
                + n.saturating_sub(1) * k.at_x,
            // g = g⁰ + G z₀ (dense, N·NU·NX) and the guess update.
            feedback: n * self.nu * self.nx + n * (k.a_x + k.b_x),
            cholesky: {
                let components = self.input_components();
                (0..self.nu)
                    .map(|g| {
                        let size = n * components.iter().filter(|&&c| c == g).count();
                        size * size * size / 6
                    })
                    .sum()
            },
        }
    }

    /// The whole `kernels.rs`.
    pub fn emit(&self, horizon: usize) -> TokenStream {
        let t = self.terms();
        let ix = |i: usize| Literal::usize_unsuffixed(i);
        // Σ of `factor(r, c, k)` over the terms, starting from `init` (or the first term).
        let sum = |terms: &[usize], init: Option<TokenStream>, factor: &dyn Fn(Literal) -> TokenStream| {
            let mut items: Vec<TokenStream> = init.into_iter().collect();
            items.extend(terms.iter().map(|&k| factor(ix(k))));
            if items.is_empty() {
                quote!(0.0)
            } else {
                quote!(#(#items)+*)
            }
        };
        let matrix = |grid: &Vec<Vec<Vec<usize>>>,
                      out: &TokenStream,
                      factor: &dyn Fn(Literal, Literal, Literal) -> TokenStream| {
            let mut stmts = Vec::new();
            for (r, row) in grid.iter().enumerate() {
                for (c, terms) in row.iter().enumerate() {
                    if terms.is_empty() {
                        continue;
                    }
                    let (rl, cl) = (ix(r), ix(c));
                    let s = sum(terms, None, &|k| factor(ix(r), ix(c), k));
                    stmts.push(quote!(#out[#rl][#cl] = #s;));
                }
            }
            stmts
        };
        let bt_p = matrix(&t.bt_p, &quote!(m), &|r, c, k| quote!(b[#k][#r] * p[#k][#c]));
        let e_b = matrix(&t.e_b, &quote!(out), &|r, c, k| quote!(e[#r][#k] * b[#k][#c]));
        let e_a = matrix(&t.e_a, &quote!(out), &|r, c, k| quote!(e[#r][#k] * a[#k][#c]));
        let pa = matrix(&t.pa, &quote!(t), &|r, c, k| quote!(p[#r][#k] * a[#k][#c]));
        let mut at_pa = matrix(&t.at_pa, &quote!(out), &|r, c, k| quote!(a[#k][#r] * t[#k][#c]));
        for (r, row) in t.at_pa.iter().enumerate() {
            for (c, terms) in row.iter().enumerate().skip(r + 1) {
                if !terms.is_empty() {
                    let (rl, cl) = (ix(r), ix(c));
                    at_pa.push(quote!(out[#cl][#rl] = out[#rl][#cl];));
                }
            }
        }
        let vector = |grid: &Vec<Vec<Vec<usize>>>,
                      init: &dyn Fn(Literal) -> Option<TokenStream>,
                      factor: &dyn Fn(Literal, Literal) -> TokenStream| {
            grid.iter()
                .enumerate()
                .filter(|(i, row)| !row[0].is_empty() || init(ix(*i)).is_some())
                .map(|(i, row)| {
                    let il = ix(i);
                    let s = sum(&row[0], init(ix(i)), &|k| factor(ix(i), k));
                    quote!(out[#il] = #s;)
                })
                .collect::<Vec<_>>()
        };
        // One loop over the chains' lanes i per output row c, all NU entries (c, r) in its body.
        let lanes = |grid: &Vec<Vec<Vec<usize>>>,
                     c: usize,
                     keep: &dyn Fn(usize) -> bool,
                     out: &dyn Fn(Literal) -> TokenStream,
                     factor: &dyn Fn(Literal, Literal) -> TokenStream| {
            grid[c]
                .iter()
                .enumerate()
                .filter(|&(r, terms)| !terms.is_empty() || keep(r))
                .map(|(r, terms)| {
                    let s = sum(terms, None, &|k| factor(k, ix(r)));
                    let o = out(ix(r));
                    quote!(#o = #s;)
                })
                .collect::<Vec<_>>()
        };
        // In place, one loop over the chains' lanes i per row c of Eᵀ (all its entries (c, r)
        // in the body), the rows in `chain_order`; a row that a later row still reads is first
        // copied to `saved` (lane by lane, in the same loop).
        let (order, saved) = self.chain_order();
        let saved_slot = |k: usize, r: usize| {
            saved
                .iter()
                .flat_map(|&s| (0..self.nu).filter(move |&r| self.e[r][s]).map(move |r| (s, r)))
                .position(|x| x == (k, r))
        };
        let saved_rows = saved
            .iter()
            .map(|&s| (0..self.nu).filter(|&r| self.e[r][s]).count())
            .sum::<usize>();
        let chains_a = order
            .iter()
            .enumerate()
            .map(|(position, &c)| {
                let cl = ix(c);
                let written = &order[..position];
                let source = |k: usize, r: usize| -> TokenStream {
                    let (kl, rl) = (ix(k), ix(r));
                    match written.contains(&k).then(|| saved_slot(k, r)).flatten() {
                        Some(slot) => {
                            let sl = ix(slot);
                            quote!(saved[#sl][i])
                        }
                        None => quote!(w[#kl][#rl][i]),
                    }
                };
                let save = (0..self.nu)
                    .filter_map(|r| {
                        let slot = saved.contains(&c).then(|| saved_slot(c, r)).flatten()?;
                        let (sl, rl) = (ix(slot), ix(r));
                        Some(quote!(saved[#sl][i] = w[#cl][#rl][i];))
                    })
                    .collect::<Vec<_>>();
                let body = t.chains_a[c]
                    .iter()
                    .enumerate()
                    .filter(|&(r, terms)| !terms.is_empty() || self.e[r][c])
                    .map(|(r, terms)| {
                        let rl = ix(r);
                        let items = terms
                            .iter()
                            .map(|&k| {
                                let (src, kl) = (source(k, r), ix(k));
                                quote!(#src * a[#kl][#cl])
                            })
                            .collect::<Vec<_>>();
                        let s = if items.is_empty() {
                            quote!(0.0)
                        } else {
                            quote!(#(#items)+*)
                        };
                        quote!(w[#cl][#rl][i] = #s;)
                    })
                    .collect::<Vec<_>>();
                quote!(for i in from..N { #(#save)* #(#body)* })
            })
            .collect::<Vec<_>>();
        let saved_len = ix(saved_rows);
        let chains_b = (0..self.nu)
            .map(|c| {
                let cl = ix(c);
                let body = lanes(
                    &t.chains_b,
                    c,
                    &|_| true,
                    &|r| quote!(t[#r][i]),
                    &|k, r| quote!(w[#k][#r][i] * b[#k][#cl]),
                );
                quote! {
                    for i in from..N { #(#body)* }
                    scatter(&t, j * NU + #cl, from, h);
                }
            })
            .collect::<Vec<_>>();
        let a_x = vector(&t.a_x, &|i| Some(quote!(y[#i])), &|i, j| quote!(a[#i][#j] * x[#j]));
        let b_x = vector(&t.b_x, &|i| Some(quote!(y[#i])), &|i, j| quote!(b[#i][#j] * v[#j]));
        let bt_x = vector(&t.bt_x, &|r| Some(quote!(y[#r])), &|r, k| quote!(b[#k][#r] * p[#k]));
        let at_x = vector(&t.at_x, &|_| None, &|i, k| quote!(a[#k][#i] * p[#k]));

        let bools = |x: &Pattern| {
            let rows = x.iter().map(|row| quote!([#(#row),*]));
            quote!([#(#rows),*])
        };
        let (pa_, pb, pp, pe) = (bools(&self.a), bools(&self.b), bools(&self.p), bools(&self.e));
        let components = self
            .input_components()
            .into_iter()
            .map(|c| Literal::u8_unsuffixed(c as u8));
        let k = self.kernel_flops();
        let (dense, after) = (Structure::dense(self.nx, self.nu).flops(horizon), self.flops(horizon));
        let (nza, nzb) = self.nonzeros();
        let doc = format!(
            " Products with the stage matrices Aₖ, Bₖ, specialised to their structural non-zeros \
             (templates/src/kernels.rs is the dense reference; generator/src/codegen/kernels.rs).\n\n\
             Structural non-zeros: Aₖ {nza} of {}, Bₖ {nzb} of {}, every Pᵢ {} of {}, every chain E {} of {}.\n\n\
             Multiply-adds per call: Bᵀ P {}, E B {}, E A {}, Aᵀ P A {}, A x {}, B v {}, Bᵀ p {}, Aᵀ p {}.\n\
             Per RTI step (N = {horizon}): condensing {} (dense {}), feedback {} (dense {}), Cholesky of the \
             condensed Hessian with every input free {} (dense {}; input components {:?}).",
            self.nx * self.nx,
            self.nx * self.nu,
            count(&self.p),
            self.nx * self.nx,
            count(&self.e),
            self.nu * self.nx,
            k.bt_p,
            k.e_b,
            k.e_a,
            k.at_p_a,
            k.a_x,
            k.b_x,
            k.bt_x,
            k.at_x,
            after.condensing,
            dense.condensing,
            after.feedback,
            dense.feedback,
            after.cholesky,
            dense.cholesky,
            self.input_components(),
        );
        quote! {
            #![doc = #doc]
            #![allow(clippy::all, unused_variables, unused_mut)]

            use crate::{Real, N, NU, NV, NX};

            /// Structural non-zeros of Aₖ = ∂F/∂x.
            pub const A_PATTERN: [[bool; NX]; NX] = #pa_;
            /// Structural non-zeros of Bₖ = ∂F/∂u.
            pub const B_PATTERN: [[bool; NU]; NX] = #pb;
            /// Structural non-zeros of every Pᵢ of the condensing recursion (closed under P ↦ Q + Aᵀ P A).
            pub const P_PATTERN: [[bool; NX]; NX] = #pp;
            /// Structural non-zeros of every chain E = Bᵢᵀ Pᵢ₊₁ Aᵢ ⋯ A_{j+1} (closed under E ↦ E A).
            pub const E_PATTERN: [[bool; NX]; NU] = #pe;

            /// Component of each input in the condensed Hessian's coupling graph: H has exact zeros
            /// between the inputs (of any stages) of different components. Numbered largest first.
            pub const INPUT_COMPONENT: [u8; NU] = [#(#components),*];

            /// Bᵀ P (P with `P_PATTERN`).
            #[inline(always)]
            pub fn bt_p(b: &[[Real; NU]; NX], p: &[[Real; NX]; NX]) -> [[Real; NX]; NU] {
                let mut m = [[0.0; NX]; NU];
                #(#bt_p)*
                m
            }

            /// E B (E with `E_PATTERN`).
            #[inline(always)]
            pub fn e_b(e: &[[Real; NX]; NU], b: &[[Real; NU]; NX]) -> [[Real; NU]; NU] {
                let mut out = [[0.0; NU]; NU];
                #(#e_b)*
                out
            }

            /// E A (E with `E_PATTERN`).
            #[inline(always)]
            pub fn e_a(e: &[[Real; NX]; NU], a: &[[Real; NX]; NX]) -> [[Real; NX]; NU] {
                let mut out = [[0.0; NX]; NU];
                #(#e_a)*
                out
            }

            /// Every chain of the condensing at once: `w[k][r][i]` is entry (r, k) of the chain Eᵢ
            /// (NU × NX) of stage i, the stages contiguous (a loop the compiler vectorises).
            pub type Chains = [[[Real; N]; NU]; NX];

            /// Rows (c, r) of the chains that `chains_a` overwrites while a later row still reads
            /// them: saved first, lane by lane.
            pub const SAVED_ROWS: usize = #saved_len;

            /// The workspace of `chains_a`.
            pub type SavedRows = [[Real; N]; SAVED_ROWS];

            /// Eᵢ ← Eᵢ A in place for the chains i in `from..N` (E with `E_PATTERN`; the terms of
            /// `e_a`). Entries outside `E_PATTERN` are neither read nor written; `saved` is
            /// scratch.
            #[inline(always)]
            pub fn chains_a(w: &mut Chains, a: &[[Real; NX]; NX], from: usize, saved: &mut SavedRows) {
                #(#chains_a)*
            }

            /// H_ij = Eᵢ B_j for the chains i in `from..N` into the condensed Hessian, and
            /// H_ji = H_ijᵀ (the terms of `e_b`).
            #[inline(always)]
            pub fn chains_b(w: &Chains, b: &[[Real; NU]; NX], j: usize, from: usize, h: &mut [[Real; NV]; NV]) {
                let j = j.min(N - 1);
                let mut t = [[0.0; N]; NU];
                #(#chains_b)*
            }

            /// H[i NU + r][col] = H[col][i NU + r] = t[r][i] for i in `from..N`.
            #[inline(always)]
            fn scatter(t: &[[Real; N]; NU], col: usize, from: usize, h: &mut [[Real; NV]; NV]) {
                let col = col.min(NV - 1);
                for i in from..N {
                    for r in 0..NU {
                        let v = t[r][i];
                        h[i * NU + r][col] = v;
                        h[col][i * NU + r] = v;
                    }
                }
            }

            /// Aᵀ (P A) (P with `P_PATTERN`): its upper triangle, mirrored (the result is exactly
            /// symmetric).
            #[inline(always)]
            pub fn at_p_a(p: &[[Real; NX]; NX], a: &[[Real; NX]; NX]) -> [[Real; NX]; NX] {
                let mut t = [[0.0; NX]; NX];
                #(#pa)*
                let mut out = [[0.0; NX]; NX];
                #(#at_pa)*
                out
            }

            /// y + A x
            #[inline(always)]
            pub fn a_x_add(a: &[[Real; NX]; NX], x: &[Real; NX], y: &[Real; NX]) -> [Real; NX] {
                let mut out = *y;
                #(#a_x)*
                out
            }

            /// y + B v
            #[inline(always)]
            pub fn b_x_add(b: &[[Real; NU]; NX], v: &[Real; NU], y: &[Real; NX]) -> [Real; NX] {
                let mut out = *y;
                #(#b_x)*
                out
            }

            /// y + Bᵀ p
            #[inline(always)]
            pub fn bt_x_add(b: &[[Real; NU]; NX], p: &[Real; NX], y: &[Real; NU]) -> [Real; NU] {
                let mut out = *y;
                #(#bt_x)*
                out
            }

            /// Aᵀ p
            #[inline(always)]
            pub fn at_x(a: &[[Real; NX]; NX], p: &[Real; NX]) -> [Real; NX] {
                let mut out = [0.0; NX];
                #(#at_x)*
                out
            }
        }
    }
}

/// Per kernel, per output entry, the inner indices of its non-zero products.
struct Terms {
    bt_p: Vec<Vec<Vec<usize>>>,
    e_b: Vec<Vec<Vec<usize>>>,
    e_a: Vec<Vec<Vec<usize>>>,
    pa: Vec<Vec<Vec<usize>>>,
    at_pa: Vec<Vec<Vec<usize>>>,
    a_x: Vec<Vec<Vec<usize>>>,
    b_x: Vec<Vec<Vec<usize>>>,
    bt_x: Vec<Vec<Vec<usize>>>,
    at_x: Vec<Vec<Vec<usize>>>,
    /// The chains' kernels, per (c, r): the same terms as `e_a`, `e_b` per (r, c).
    chains_a: Vec<Vec<Vec<usize>>>,
    chains_b: Vec<Vec<Vec<usize>>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pat(rows: &[&[u8]]) -> Pattern {
        rows.iter().map(|r| r.iter().map(|&v| v != 0).collect()).collect()
    }

    #[test]
    fn double_integrator_by_hand() {
        // ẋ₀ = x₁, ẋ₁ = u: A = [[1, h], [0, 1]], B = [[h²/2], [h]]; Q weighs x₀ only.
        let s = Structure::new(
            &pat(&[&[0, 1], &[0, 0]]),
            &pat(&[&[0], &[1]]),
            1,
            &[1.0, 0.0],
            &[1.0, 0.0],
        );
        assert_eq!(s.a, pat(&[&[1, 1], &[0, 1]]));
        assert_eq!(s.b, pat(&[&[1], &[1]]));
        assert_eq!(s.s, pat(&[&[1, 1, 1], &[0, 1, 1]]));
        assert_eq!(s.input_components(), vec![0]);
        // P_N = diag(1, 0); Aᵀ P_N A = [[1, h], [h, h²]]: full.
        assert_eq!(s.p, pat(&[&[1, 1], &[1, 1]]));
        assert_eq!(s.e, pat(&[&[1, 1]]));
        let k = s.kernel_flops();
        // Bᵀ P: 2 entries × 2 terms; E B: 2; E A: entry 0 has 1 term (a₁₀ = 0), entry 1 has 2;
        // P A: 3 + 3 (column 0 skips a₁₀); Aᵀ (PA), upper triangle: row 0 has a₀₀ only (2
        // entries), row 1 both (entry (1, 1)): 2 + 2.
        assert_eq!((k.bt_p, k.e_b, k.e_a, k.at_p_a), (4, 2, 3, 6 + 4));
        assert_eq!((k.a_x, k.b_x, k.bt_x, k.at_x), (3, 2, 2, 3));
        let dense = Structure::dense(2, 1).kernel_flops();
        assert_eq!((dense.bt_p, dense.e_b, dense.e_a, dense.at_p_a), (4, 2, 4, 8 + 6));
        // N = 3: 3 (4 + 2) + 3 (3 + 2) + 2 · 10, then G: 3 · 3, g⁰: 3 · 3 + 3 · 2 + 2 · 3
        assert_eq!(s.flops(3).condensing, 18 + 15 + 20 + 9 + 9 + 6 + 6);
        // g⁰ + G z₀: 3 · 1 · 2; the guess update 3 (3 + 2)
        assert_eq!(s.flops(3).feedback, 6 + 15);
    }

    #[test]
    fn decoupled_axes_stay_decoupled() {
        // Two independent integrators x₀' = u₀, x₁' = u₁, only x₀ weighed: nothing couples them.
        let s = Structure::new(
            &pat(&[&[0, 0], &[0, 0]]),
            &pat(&[&[1, 0], &[0, 1]]),
            2,
            &[1.0, 0.0],
            &[1.0, 0.0],
        );
        assert_eq!(s.a, pat(&[&[1, 0], &[0, 1]]));
        assert_eq!(s.b, pat(&[&[1, 0], &[0, 1]]));
        assert_eq!(s.p, pat(&[&[1, 0], &[0, 0]]));
        assert_eq!(s.e, pat(&[&[1, 0], &[0, 0]]));
        assert_eq!(s.kernel_flops().e_a, 1);
        assert_eq!(s.input_components(), vec![0, 1]);
    }

    #[test]
    fn emitted_kernels_parse() {
        let s = Structure::new(
            &pat(&[&[0, 1], &[0, 0]]),
            &pat(&[&[0], &[1]]),
            1,
            &[1.0, 0.0],
            &[1.0, 0.0],
        );
        let file: syn::File = syn::parse2(s.emit(3)).expect("emitted kernels parse");
        assert!(file.items.len() > 8);
    }
}
