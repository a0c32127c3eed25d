//! Emits the `model` module: ẋ = f(x, u), its Jacobians and the stage
//! sensitivity used by the spliced RK4, as straight-line code.

use crate::ir::ModelIr;
use crate::symbolic::emit::local_ident;
use crate::symbolic::{float_literal, Emitter, Float, NonFiniteConstant};
use proc_macro2::TokenStream;
use quote::{format_ident, quote};
use std::collections::BTreeSet;

/// Locals the emitted functions use besides the model's variables.
const RESERVED: &[&str] = &[
    "x", "u", "s", "f", "ds", "j", "jv", "fx", "fu", "Real", "NX", "NU", "NZ", "NJ", "Sens",
];

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

/// Multiply-adds of the emitted RK4 sensitivity kernels (products ∂f/∂x · Y, a coefficient-one term
/// and a ∂f/∂u term counting as their additions and a copied entry as 0, and the combinations
/// ACC += 2 D, Y = S + a D, S += c (ACC + D), an assignment counting 0) of one substep: the first of
/// a sample (from S = [I 0], `sensitivity_stage*_at_identity`) and a later one
/// (`sensitivity_stage*`), as emitted; and over all NZ columns (`stage_dense` per stage product,
/// `combine_dense` per substep: the code before the columns were specialised).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SensitivityFlops {
    pub first_substep: usize,
    pub later_substep: usize,
    pub stage_dense: usize,
    pub combine_dense: usize,
}

impl SensitivityFlops {
    /// Per RTI step (N = `horizon` samples of `substeps` substeps): (emitted, dense).
    pub fn per_step(&self, horizon: usize, substeps: usize) -> (usize, usize) {
        let n = horizon * substeps;
        (
            horizon * (self.first_substep + substeps.saturating_sub(1) * self.later_substep),
            n * (4 * self.stage_dense + self.combine_dense),
        )
    }
}

type Pattern = Vec<Vec<bool>>;

/// How a structural non-zero of [∂f/∂x ∂f/∂u] enters the stage kernels.
enum Coef {
    /// Identically 1: the term is the factor itself.
    One,
    /// A constant: its literal.
    Literal(TokenStream),
    /// Computed by `continuous_derivatives`: `jv[index]`.
    Value(usize),
}

impl Coef {
    fn value(&self) -> TokenStream {
        match self {
            Coef::One => quote!(1.0),
            Coef::Literal(l) => l.clone(),
            Coef::Value(n) => {
                let n = index(*n);
                quote!(jv[#n])
            }
        }
    }

    fn times(&self, factor: TokenStream) -> TokenStream {
        match self {
            Coef::One => factor,
            c => {
                let c = c.value();
                quote!(#c * #factor)
            }
        }
    }
}

/// The structural non-zeros of [∂f/∂x ∂f/∂u] by row: (column, coefficient), x columns first.
struct Jacobian {
    nx: usize,
    nz: usize,
    rows: Vec<Vec<(usize, Coef)>>,
}

/// Which of the eight stage kernels (docs/discretisation.md).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Stage {
    /// ACC = D, Y = S + a D with D at Y = S.
    First,
    /// ACC += 2 D, Y⁺ = S + a D.
    Middle,
    /// S += c (ACC + D).
    Last,
}

/// One emitted stage kernel's statements, its multiply-adds and the patterns it leaves.
struct StageCode {
    stmts: Vec<TokenStream>,
    flops: usize,
    /// Of ACC after the stage.
    acc: Pattern,
    /// Of the Y it writes (First, Middle) or of S (Last).
    out: Pattern,
}

impl Jacobian {
    /// Entry (i, j) of D = ∂f/∂x · Y + ∂f/∂u · [0 I] with Y (the array `name`) of pattern `y` (`None`: Y = [I 0],
    /// D = [∂f/∂x ∂f/∂u], no products), and its multiply-adds; `None` if structurally zero. The terms
    /// in the order of the dense sum, the ∂f/∂u term last.
    fn d(&self, i: usize, j: usize, y: Option<&[Vec<bool>]>, name: &TokenStream) -> Option<(TokenStream, usize)> {
        let Some(y) = y else {
            return self.rows[i].iter().find(|(k, _)| *k == j).map(|(_, c)| (c.value(), 0));
        };
        let (jj, nx) = (index(j), self.nx);
        let mut terms: Vec<TokenStream> = self.rows[i]
            .iter()
            .filter(|(k, _)| *k < nx && y[*k][j])
            .map(|(k, c)| {
                let k = index(*k);
                c.times(quote!(#name[#k][#jj]))
            })
            .collect();
        // A lone coefficient-one term is a copy.
        let copy = terms.len() == 1
            && self.rows[i]
                .iter()
                .any(|(k, c)| *k < nx && y[*k][j] && matches!(c, Coef::One));
        let mut flops = if copy { 0 } else { terms.len() };
        if let Some((_, c)) = self.rows[i].iter().find(|(k, _)| *k == j && j >= nx) {
            terms.push(c.value());
            flops += 1;
        }
        (!terms.is_empty()).then(|| (quote!(#(#terms)+*), flops))
    }

    /// The statements of one stage kernel. `s`: the pattern of S (`at_identity`: S = [I 0], not
    /// read); `y`: of the stage's Y (`None` for the first stage: Y = S); `acc`: of ACC before it
    /// (ignored by the first stage, which assigns it). Each entry is written from the terms that
    /// are structurally non-zero, the values those of the dense recursion (a sum with zeros).
    fn stage(
        &self,
        kind: Stage,
        at_identity: bool,
        s: &[Vec<bool>],
        y: Option<&[Vec<bool>]>,
        acc: &[Vec<bool>],
    ) -> StageCode {
        let y = match (kind, at_identity) {
            (Stage::First, true) => None,
            (Stage::First, false) => Some(s),
            _ => y,
        };
        let mut stmts = Vec::new();
        let mut flops = 0;
        let mut acc_out = if kind == Stage::First {
            vec![vec![false; self.nz]; self.nx]
        } else {
            acc.to_vec()
        };
        let mut out = s.to_vec();
        // Stage 1 reads Y = S itself.
        let name = if kind == Stage::First { quote!(s) } else { quote!(y) };
        for i in 0..self.nx {
            for j in 0..self.nz {
                let (ii, jj) = (index(i), index(j));
                let d = self.d(i, j, y, &name);
                let has_s = s[i][j];
                // S's entry as a token: read, or the identity's 1 (its 0s are structural).
                let s_tok = if at_identity { quote!(1.0) } else { quote!(s[#ii][#jj]) };
                if let Some((expr, f)) = &d {
                    flops += f;
                    stmts.push(quote!(let d = #expr;));
                }
                match kind {
                    Stage::First | Stage::Middle => {
                        if d.is_some() {
                            if kind == Stage::First {
                                stmts.push(quote!(acc[#ii][#jj] = d;));
                            } else if acc[i][j] {
                                stmts.push(quote!(acc[#ii][#jj] += 2.0 * d;));
                                flops += 1;
                            } else {
                                stmts.push(quote!(acc[#ii][#jj] = 2.0 * d;));
                                flops += 1;
                            }
                            acc_out[i][j] = true;
                        }
                        let target = if kind == Stage::First {
                            quote!(y)
                        } else {
                            quote!(y_next)
                        };
                        let value = match (has_s, d.is_some()) {
                            (true, true) => Some(quote!(#s_tok + a * d)),
                            (true, false) => Some(s_tok),
                            (false, true) => Some(quote!(a * d)),
                            (false, false) => None,
                        };
                        if let Some(v) = value {
                            flops += usize::from(d.is_some());
                            stmts.push(quote!(#target[#ii][#jj] = #v;));
                            out[i][j] = true;
                        }
                    }
                    Stage::Last => {
                        let step = match (acc[i][j], d.is_some()) {
                            (true, true) => Some((quote!(c * (acc[#ii][#jj] + d)), 2)),
                            (true, false) => Some((quote!(c * acc[#ii][#jj]), 1)),
                            (false, true) => Some((quote!(c * d), 1)),
                            (false, false) => None,
                        };
                        if let Some((e, f)) = step {
                            flops += f;
                            out[i][j] = true;
                            stmts.push(match (at_identity, has_s) {
                                (false, _) => quote!(s[#ii][#jj] += #e;),
                                (true, true) => quote!(s[#ii][#jj] = 1.0 + #e;),
                                (true, false) => quote!(s[#ii][#jj] = #e;),
                            });
                        }
                    }
                }
            }
        }
        StageCode {
            stmts,
            flops,
            acc: acc_out,
            out,
        }
    }

    /// The four kernels of a substep from S of pattern `s` (`at_identity`: S = [I 0]), their
    /// multiply-adds and the pattern of S after it.
    fn substep(&self, s: &[Vec<bool>], at_identity: bool) -> ([Vec<TokenStream>; 4], usize, Pattern) {
        let none = vec![vec![false; self.nz]; self.nx];
        let k1 = self.stage(Stage::First, at_identity, s, None, &none);
        let k2 = self.stage(Stage::Middle, at_identity, s, Some(&k1.out), &k1.acc);
        let k3 = self.stage(Stage::Middle, at_identity, s, Some(&k2.out), &k2.acc);
        let k4 = self.stage(Stage::Last, at_identity, s, Some(&k3.out), &k3.acc);
        let flops = k1.flops + k2.flops + k3.flops + k4.flops;
        ([k1.stmts, k2.stmts, k3.stmts, k4.stmts], flops, k4.out)
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

    // continuous_derivatives: f and the values of [∂f/∂x ∂f/∂u] the stage kernels read (the
    // structural non-zeros that are neither 1 nor another constant), sharing one DAG walk.
    let mut em = Emitter::new(g, vars, float);
    let sf_atoms: Vec<TokenStream> = ir.f.iter().map(|&id| em.atom(id)).collect();
    let mut jv_assign = Vec::new();
    let mut jac = Jacobian {
        nx: ir.nx,
        nz: nz_count,
        rows: Vec::new(),
    };
    for (rx, ru) in ir.fx.iter().zip(&ir.fu) {
        let mut row = Vec::new();
        for (k, &d) in rx
            .iter()
            .enumerate()
            .chain(ru.iter().enumerate().map(|(m, d)| (ir.nx + m, d)))
        {
            if g.is_zero(d) {
                continue;
            }
            let coef = if g.is_one(d) {
                Coef::One
            } else if let Some(v) = g.as_const(d) {
                Coef::Literal(float_literal(v, float)?)
            } else {
                let n = jv_assign.len();
                let a = em.atom(d);
                let nn = index(n);
                jv_assign.push(quote!(jv[#nn] = #a;));
                Coef::Value(n)
            };
            row.push((k, coef));
        }
        // The dense products (every column) of the code before the columns were specialised.
        let xs: Vec<&(usize, Coef)> = row.iter().filter(|(k, _)| *k < ir.nx).collect();
        if !matches!(xs.as_slice(), [] | [(_, Coef::One)]) {
            flops.stage_dense += xs.len() * nz_count;
        }
        flops.stage_dense += row.len() - xs.len();
        jac.rows.push(row);
    }
    em.check()?;
    let sf_stmts = em.take_statements();
    used.extend(em.used_functions());
    let nj = index(jv_assign.len());

    // The stage kernels: of the first substep of a sample, from S = [I 0] (the patterns the
    // recursion has from there), and of a later one, over `s_pattern`.
    let mut identity = vec![vec![false; nz_count]; ir.nx];
    for (i, row) in identity.iter_mut().enumerate() {
        row[i] = true;
    }
    let ([i1, i2, i3, i4], first_flops, after_first) = jac.substep(&identity, true);
    let ([g1, g2, g3, g4], later_flops, _) = jac.substep(s_pattern, false);
    // The generator's propagation (kernels::Structure) covers the first substep's S.
    debug_assert!(after_first
        .iter()
        .flatten()
        .zip(s_pattern.iter().flatten())
        .all(|(a, s)| !a || *s));
    flops.first_substep = first_flops;
    flops.later_substep = later_flops;
    flops.combine_dense = 7 * ir.nx * nz_count;
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

        /// A sensitivity-shaped matrix (NX × NZ): S = ∂x/∂(x₀, u), a stage's S + a D, or the RK4 sum
        /// D1 + 2 D2 + 2 D3 of a substep.
        pub type Sens = [[Real; NZ]; NX];

        /// Number of values `continuous_derivatives` writes.
        pub const NJ: usize = #nj;

        /// f(x, u), writing the values of [∂f/∂x ∂f/∂u] the stage kernels read into `jv` (the
        /// structural non-zeros other than constants, row by row): one walk of the expression graph.
        pub fn continuous_derivatives(x: &[Real; NX], u: &[Real; NU], jv: &mut [Real; NJ]) -> [Real; NX] {
            #binding
            #(#sf_stmts)*
            #(#jv_assign)*
            [#(#sf_atoms),*]
        }

        /// Structural non-zeros of every sensitivity S = ∂x/∂(x₀, u) of the RK4 recursion (the
        /// generator's propagation of the Jacobian pattern; S = [A B] at the end of a sample).
        #[allow(dead_code)] // what the later substeps' kernels below were specialised to
        pub const S_PATTERN: [[bool; NZ]; NX] = [#(#pattern_rows),*];

        // The RK4 stages of one substep (templates/src/model.rs has the dense reference): with
        // D = ∂f/∂x · Y + ∂f/∂u · [0 I] at the stage's Y, stage 1 (Y = S) sets ACC = D and writes the
        // next Y = S + a D, stages 2 and 3 add 2 D to ACC and write S + a D, stage 4 updates
        // S += c (ACC + D). Straight-line code over the entries that may be non-zero: `_at_identity`
        // for the first substep of a sample (S = [I 0] on entry, not read), the others over S_PATTERN.
        // Each kernel reads Y and ACC only where the kernel before wrote them.

        /// Stage 1 at S = [I 0]: ACC = D = [∂f/∂x ∂f/∂u], Y = [I 0] + a D.
        pub fn sensitivity_stage1_at_identity(jv: &[Real; NJ], a: Real, acc: &mut Sens, y: &mut Sens) {
            #(#i1)*
        }

        /// Stage 2 at S = [I 0]: ACC += 2 D, Y⁺ = [I 0] + a D.
        pub fn sensitivity_stage2_at_identity(jv: &[Real; NJ], y: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
            #(#i2)*
        }

        /// Stage 3 at S = [I 0]: ACC += 2 D, Y⁺ = [I 0] + a D.
        pub fn sensitivity_stage3_at_identity(jv: &[Real; NJ], y: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
            #(#i3)*
        }

        /// Stage 4 from S = [I 0]: S = [I 0] + c (ACC + D).
        pub fn sensitivity_stage4_at_identity(jv: &[Real; NJ], y: &Sens, c: Real, acc: &Sens, s: &mut Sens) {
            #(#i4)*
        }

        /// Stage 1: ACC = D, Y = S + a D with D at Y = S.
        pub fn sensitivity_stage1(jv: &[Real; NJ], s: &Sens, a: Real, acc: &mut Sens, y: &mut Sens) {
            #(#g1)*
        }

        /// Stage 2: ACC += 2 D, Y⁺ = S + a D.
        pub fn sensitivity_stage2(jv: &[Real; NJ], y: &Sens, s: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
            #(#g2)*
        }

        /// Stage 3: ACC += 2 D, Y⁺ = S + a D.
        pub fn sensitivity_stage3(jv: &[Real; NJ], y: &Sens, s: &Sens, a: Real, acc: &mut Sens, y_next: &mut Sens) {
            #(#g3)*
        }

        /// Stage 4: S += c (ACC + D).
        pub fn sensitivity_stage4(jv: &[Real; NJ], y: &Sens, c: Real, acc: &Sens, s: &mut Sens) {
            #(#g4)*
        }
    };
    Ok((tokens, used, flops))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codegen::kernels::Structure;

    fn pat(rows: &[&[u8]]) -> Pattern {
        rows.iter().map(|r| r.iter().map(|&v| v != 0).collect()).collect()
    }

    #[test]
    fn oscillator_stage_kernels_by_hand() {
        // ẋ₀ = x₁, ẋ₁ = c(x) x₀ + u: [∂f/∂x ∂f/∂u] = [[0, 1, 0], [jv₀, 0, 1]].
        let jac = Jacobian {
            nx: 2,
            nz: 3,
            rows: vec![vec![(1, Coef::One)], vec![(0, Coef::Value(0)), (2, Coef::One)]],
        };
        let (kernels, flops, after) = jac.substep(&pat(&[&[1, 0, 0], &[0, 1, 0]]), true);
        // Stage 1: Y₁ = I + a J, 3 entries a·d (the diagonal is copied). Stage 2 (Y₁ full but for
        // (0, 2)): row 0 copies, row 1 jv₀ y₀ⱼ for j = 0, 1 and the ∂f/∂u term alone for j = 2 (3);
        // ACC 6, Y 6. Stage 3 (Y₂ full): products 1 + 1 + 2, ACC 6, Y 6. Stage 4: products 4, 2 per
        // entry of S (6).
        assert_eq!(flops, 3 + (3 + 6 + 6) + (4 + 6 + 6) + (4 + 12));
        let structure = Structure::new(
            &pat(&[&[0, 1], &[1, 0]]),
            &pat(&[&[0], &[1]]),
            1,
            &[1.0, 1.0],
            &[1.0, 1.0],
        );
        assert_eq!(after, structure.s);
        // The first stage needs no products: the derivatives themselves.
        let first = kernels[0].iter().map(|t| t.to_string()).collect::<Vec<_>>().join(" ");
        assert!(!first.contains("= y [") && !first.contains("* y ["), "{first}");
        // A later substep from the full pattern stays in it.
        let (_, later, after_later) = jac.substep(&structure.s, false);
        assert_eq!(after_later, structure.s);
        assert!(later > flops);
    }
}
