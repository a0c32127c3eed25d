//! Emits the `model` module: ẋ = f(x, u), its Jacobians and the stage
//! sensitivity used by the spliced RK4, as straight-line code.

use crate::ir::ModelIr;
use crate::symbolic::emit::local_ident;
use crate::symbolic::{Emitter, Float, Id, NonFiniteConstant};
use proc_macro2::TokenStream;
use quote::{format_ident, quote};
use std::collections::BTreeSet;

/// Locals the emitted functions use besides the model's variables.
const RESERVED: &[&str] = &["x", "u", "s", "f", "ds", "j", "fx", "fu", "Real", "NX", "NU", "NZ"];

/// Bindings `let ([x, y, …], [u_vz, …]) = (*x, *u);` and the variable tokens.
fn bind_variables(ir: &ModelIr) -> (TokenStream, Vec<TokenStream>) {
    let names: Vec<String> = ir.state_names.iter().chain(&ir.input_names).cloned().collect();
    let idents: Vec<_> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            // The parameters x and u are destructured in one statement, so a
            // state named `x` may keep its name.
            let reserved: Vec<&str> = RESERVED.iter().copied().filter(|r| *r != "x" && *r != "u").collect();
            let fallback = if i < ir.nx {
                format!("x_{i}")
            } else {
                format!("u_{}", i - ir.nx)
            };
            let fallback_taken = names.contains(&fallback);
            let fallback = if fallback_taken {
                format!("{fallback}_v")
            } else {
                fallback
            };
            local_ident(n, &fallback, &reserved)
        })
        .collect();
    let (xs, us) = idents.split_at(ir.nx);
    let binding = quote!(let ([#(#xs),*], [#(#us),*]) = (*x, *u););
    let tokens = idents.iter().map(|i| quote!(#i)).collect();
    (binding, tokens)
}

fn math_imports(used: &BTreeSet<&'static str>) -> TokenStream {
    if used.is_empty() {
        return quote!();
    }
    let used = used.iter().map(|f| format_ident!("{}", f));
    quote!(use crate::math::{#(#used),*};)
}

fn index(i: usize) -> proc_macro2::Literal {
    proc_macro2::Literal::usize_unsuffixed(i)
}

/// Multiply-adds of one `continuous_sensitivity` call (∂f/∂x · S, a coefficient-one term and a
/// copied row count as their additions, 0 for a copy) and of the RK4 sensitivity updates of one
/// substep (3 `sensitivity_axpy`, 4 per entry in `sensitivity_step`), as emitted (`after`) and
/// over all NZ columns (`dense`, the code before the columns were specialised).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SensitivityFlops {
    pub stage: usize,
    pub stage_dense: usize,
    pub combine: usize,
    pub combine_dense: usize,
}

impl SensitivityFlops {
    /// Per RTI step: N samples × `substeps` × (4 stages + the combinations), less one stage per
    /// sample in the emitted code (its first stage is at S = [I 0]: no products,
    /// `continuous_sensitivity_at_identity`).
    pub fn per_step(&self, horizon: usize, substeps: usize) -> (usize, usize) {
        let n = horizon * substeps;
        (
            n * (4 * self.stage + self.combine) - horizon * self.stage,
            n * (4 * self.stage_dense + self.combine_dense),
        )
    }
}

/// The whole `model.rs` as tokens, the math functions it calls and the multiply-adds of its
/// sensitivity kernels. `s_pattern` (NX × NZ): the structural non-zeros of every sensitivity
/// S = ∂x/∂(x₀, u) the RK4 recursion forms ([`super::kernels::Structure::s`]); the emitted
/// sensitivity code computes and combines only those columns.
pub fn emit(
    ir: &ModelIr,
    float: Float,
    s_pattern: &[Vec<bool>],
) -> Result<(TokenStream, BTreeSet<&'static str>, SensitivityFlops), NonFiniteConstant> {
    let nz_count = ir.nx + ir.nu;
    let mut flops = SensitivityFlops::default();
    let g = &ir.graph;
    let (binding, vars) = bind_variables(ir);

    // continuous_dynamics
    let mut em = Emitter::new(g, vars.clone(), float);
    let f_atoms: Vec<TokenStream> = ir.f.iter().map(|&id| em.atom(id)).collect();
    em.check()?;
    let f_stmts = em.take_statements();
    let mut used = em.used_functions().clone();

    // continuous_jacobians: only structural non-zeros are assigned.
    let mut em = Emitter::new(g, vars.clone(), float);
    let mut jac_assign = Vec::new();
    for (i, (rx, ru)) in ir.fx.iter().zip(&ir.fu).enumerate() {
        for (j, &d) in rx.iter().enumerate() {
            if !g.is_zero(d) {
                let a = em.atom(d);
                let (i, j) = (index(i), index(j));
                jac_assign.push(quote!(fx[#i][#j] = #a;));
            }
        }
        for (j, &d) in ru.iter().enumerate() {
            if !g.is_zero(d) {
                let a = em.atom(d);
                let (i, j) = (index(i), index(j));
                jac_assign.push(quote!(fu[#i][#j] = #a;));
            }
        }
    }
    em.check()?;
    let jac_stmts = em.take_statements();
    used.extend(em.used_functions());

    // continuous_sensitivity: f and ∂f/∂x·S + ∂f/∂u·[0 I] sharing one DAG walk.
    let mut em = Emitter::new(g, vars.clone(), float);
    let sf_atoms: Vec<TokenStream> = ir.f.iter().map(|&id| em.atom(id)).collect();
    let mut rows = Vec::new();
    for (i, (rx, ru)) in ir.fx.iter().zip(&ir.fu).enumerate() {
        let nz: Vec<(usize, Id)> = rx.iter().copied().enumerate().filter(|(_, d)| !g.is_zero(*d)).collect();
        let ii = index(i);
        let row = match nz.as_slice() {
            [] => quote!(),
            [(k, d)] if g.is_one(*d) => {
                let k = index(*k);
                quote!(ds[#ii] = s[#k];)
            }
            _ => {
                let atoms: Vec<(usize, Option<TokenStream>)> = nz
                    .iter()
                    .map(|&(k, d)| (k, if g.is_one(d) { None } else { Some(em.atom(d)) }))
                    .collect();
                flops.stage_dense += atoms.len() * nz_count;
                // Only the columns S may have non-zero, and in each only the products whose
                // S entry may be non-zero (in the order of the dense sum).
                let mut stmts = Vec::new();
                for j in (0..nz_count).filter(|&j| s_pattern[i][j]) {
                    let jj = index(j);
                    let terms: Vec<TokenStream> = atoms
                        .iter()
                        .filter(|(k, _)| s_pattern[*k][j])
                        .map(|(k, a)| {
                            let k = index(*k);
                            match a {
                                None => quote!(s[#k][#jj]),
                                Some(a) => quote!(#a * s[#k][#jj]),
                            }
                        })
                        .collect();
                    flops.stage += terms.len();
                    if !terms.is_empty() {
                        stmts.push(quote!(ds[#ii][#jj] = #(#terms)+*;));
                    }
                }
                quote!(#(#stmts)*)
            }
        };
        let mut extra = Vec::new();
        for (m, &d) in ru.iter().enumerate() {
            if !g.is_zero(d) {
                let a = em.atom(d);
                let col = index(ir.nx + m);
                extra.push(quote!(ds[#ii][#col] += #a;));
                flops.stage += 1;
                flops.stage_dense += 1;
            }
        }
        rows.push(quote!(#row #(#extra)*));
    }
    em.check()?;
    let s_stmts = em.take_statements();

    // continuous_sensitivity_at_identity: the same at S = [I 0] (the first stage of a sample),
    // where ∂f/∂x · S + ∂f/∂u · [0 I] = [∂f/∂x ∂f/∂u]: the derivatives themselves, no products.
    let mut em = Emitter::new(g, vars, float);
    let f0_atoms: Vec<TokenStream> = ir.f.iter().map(|&id| em.atom(id)).collect();
    let mut first = Vec::new();
    for (i, (rx, ru)) in ir.fx.iter().zip(&ir.fu).enumerate() {
        let ii = index(i);
        for (k, &d) in rx
            .iter()
            .enumerate()
            .chain(ru.iter().enumerate().map(|(m, d)| (ir.nx + m, d)))
        {
            if !g.is_zero(d) {
                let a = em.atom(d);
                let kk = index(k);
                first.push(quote!(ds[#ii][#kk] = #a;));
            }
        }
    }
    em.check()?;
    let first_stmts = em.take_statements();
    used.extend(em.used_functions());

    let entries: Vec<(proc_macro2::Literal, proc_macro2::Literal)> = (0..ir.nx)
        .flat_map(|i| {
            (0..nz_count)
                .filter(move |&j| s_pattern[i][j])
                .map(move |j| (index(i), index(j)))
        })
        .collect();
    flops.combine = 7 * entries.len();
    flops.combine_dense = 7 * ir.nx * nz_count;
    let axpy: Vec<TokenStream> = entries
        .iter()
        .map(|(i, j)| quote!(y[#i][#j] += a * d[#i][#j];))
        .collect();
    let step: Vec<TokenStream> = entries
        .iter()
        .map(|(i, j)| quote!(s[#i][#j] += c * (d1[#i][#j] + 2.0 * d2[#i][#j] + 2.0 * d3[#i][#j] + d4[#i][#j]);))
        .collect();
    let pattern_rows = s_pattern.iter().map(|row| quote!([#(#row),*]));
    used.extend(em.used_functions());
    let imports = math_imports(&used);
    let state_list = ir.state_names.join(", ");
    let input_list = ir.input_names.join(", ");
    let f_doc = format!(" ẋ = f(x, u) with x = [{state_list}] and u = [{input_list}].");
    let tokens = quote! {
        //! Continuous-time model ẋ = f(x, u) and its analytic derivatives.
        #![allow(clippy::all, unused_variables, unused_mut, non_snake_case)]

        use crate::{Real, NU, NX, NZ};
        #imports

        #[doc = #f_doc]
        pub fn continuous_dynamics(x: &[Real; NX], u: &[Real; NU]) -> [Real; NX] {
            #binding
            #(#f_stmts)*
            [#(#f_atoms),*]
        }

        /// (∂f/∂x, ∂f/∂u) with `fx[i][j] = ∂fᵢ/∂xⱼ`, `fu[i][j] = ∂fᵢ/∂uⱼ`; structural zeros are not computed.
        pub fn continuous_jacobians(x: &[Real; NX], u: &[Real; NU]) -> ([[Real; NX]; NX], [[Real; NU]; NX]) {
            #binding
            let mut fx = [[0.0; NX]; NX];
            let mut fu = [[0.0; NU]; NX];
            #(#jac_stmts)*
            #(#jac_assign)*
            (fx, fu)
        }

        /// (f(x, u), ∂f/∂x · S + ∂f/∂u · [0 I]) for a sensitivity S = ∂x/∂(x₀, u):
        /// one RK4 stage of the forward sensitivity recursion. Rows skip structural zeros of ∂f/∂x.
        pub fn continuous_sensitivity(x: &[Real; NX], u: &[Real; NU], s: &[[Real; NZ]; NX]) -> ([Real; NX], [[Real; NZ]; NX]) {
            #binding
            #(#s_stmts)*
            let f = [#(#sf_atoms),*];
            let mut ds = [[0.0; NZ]; NX];
            #(#rows)*
            (f, ds)
        }

        /// [`continuous_sensitivity`] at S = [I 0] (the first stage of a sample): (f(x, u),
        /// [∂f/∂x ∂f/∂u]), the derivatives written where the product would have summed them with
        /// zeros.
        pub fn continuous_sensitivity_at_identity(x: &[Real; NX], u: &[Real; NU]) -> ([Real; NX], [[Real; NZ]; NX]) {
            #binding
            #(#first_stmts)*
            let f = [#(#f0_atoms),*];
            let mut ds = [[0.0; NZ]; NX];
            #(#first)*
            (f, ds)
        }

        /// Structural non-zeros of every sensitivity S = ∂x/∂(x₀, u) of the RK4 recursion (the
        /// generator's propagation of the Jacobian pattern; S = [A B] at the end of a sample).
        #[allow(dead_code)] // what the two kernels below were specialised to
        pub const S_PATTERN: [[bool; NZ]; NX] = [#(#pattern_rows),*];

        /// Y = S + a D over `S_PATTERN` (outside it both are zero).
        #[inline(always)]
        pub fn sensitivity_axpy(s: &[[Real; NZ]; NX], a: Real, d: &[[Real; NZ]; NX]) -> [[Real; NZ]; NX] {
            let mut y = *s;
            #(#axpy)*
            y
        }

        /// S += c (D1 + 2 D2 + 2 D3 + D4) over `S_PATTERN`.
        #[inline(always)]
        pub fn sensitivity_step(
            s: &mut [[Real; NZ]; NX],
            c: Real,
            d1: &[[Real; NZ]; NX],
            d2: &[[Real; NZ]; NX],
            d3: &[[Real; NZ]; NX],
            d4: &[[Real; NZ]; NX],
        ) {
            #(#step)*
        }
    };
    Ok((tokens, used, flops))
}
