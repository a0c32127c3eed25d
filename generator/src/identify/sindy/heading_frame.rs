//! The horizontal rows fitted in the heading frame (docs/identification.md, "Heading frame").
//!
//! Physically the horizontal force is the thrust tilted by roll and pitch and rotated by the
//! heading: `[v̇x, v̇y] = Rz(ψ) · F(roll, pitch, v_h, …)`, with `v_h = Rz(−ψ)·[vx, vy]` the velocity in
//! the heading frame. A world-frame library carries that rotation through `a·cos ψ`, `a·sin ψ`
//! terms, which flights at one heading cannot identify (they are collinear with `a`: see
//! "Unexcited directions"); dropping them leaves a model of the logged heading only.
//!
//! Here the vx and vy rows are fitted **jointly** as one regression over the heading-frame library
//! Θ_h ([`heading_frame_library`]: no yaw, the horizontal velocity as `v_h`), with the unknown
//! heading-frame rows ξ_f (forward) and ξ_l (lateral):
//!
//! ```text
//!   v̇x = cos ψ · Θ_h ξ_f − sin ψ · Θ_h ξ_l
//!   v̇y = sin ψ · Θ_h ξ_f + cos ψ · Θ_h ξ_l
//! ```
//!
//! (2N equations, 2p unknowns; the integral form averages each design row over the interval's two
//! ends, so it is exact for a turning heading too). With the heading still, the columns of ξ_f and
//! ξ_l are orthogonal and the joint fit is the fit of the rotated targets `Rz(−ψ)·[v̇x, v̇y]`.
//!
//! The rows are then **written back in world coordinates**: each `θ_h · cos ψ` (and `· sin ψ`),
//! with `v_f = cos ψ·vx + sin ψ·vy` and `v_l = −sin ψ·vx + cos ψ·vy` substituted, is expanded into
//! products of the model grammar (`u_roll*cos(yaw)`, `vx*cos(yaw)^2`, …; `sin(yaw)^2` reduced to
//! `1 − cos(yaw)^2`), so the model file stays an ordinary SINDy model in world coordinates, and
//! heading-equivariant by construction whatever heading the data held.

use super::library::{eval_term, Library, PHYSICS_STATES};
use crate::model::{Base, Term, DEFAULT_INPUTS};
use std::collections::BTreeMap;

/// Index of yaw, vx and vy in the 16 variables (states then inputs).
pub const YAW: usize = 5;
pub const VX: usize = 6;
pub const VY: usize = 7;

/// When the vx and vy rows are fitted in the heading frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HeadingFrame {
    /// When the logs did not excite the heading (yaw among the excluded variables) — the default.
    Auto,
    /// Always (physics library, dynamic rows).
    Always,
    /// Never: the world-frame library for every row.
    Never,
}

impl HeadingFrame {
    pub fn name(self) -> &'static str {
        match self {
            HeadingFrame::Auto => "auto",
            HeadingFrame::Always => "always",
            HeadingFrame::Never => "never",
        }
    }
}

/// The heading-frame library of the horizontal rows, 56 terms: `1`; `sin(roll)`, `sin(pitch)` (the
/// thrust direction) and the other 6 invariant states (`vx`, `vy` here standing for the
/// heading-frame velocities v_f, v_l); the 4 inputs; the 8 squares of the physics library's
/// invariant states; their 32 products with the inputs; `cos(roll)`, `cos(pitch)`,
/// `cos(roll)*cos(pitch)`. No yaw.
pub fn heading_frame_library() -> Vec<String> {
    let mut t = vec!["1".to_string()];
    t.extend(PHYSICS_STATES.iter().map(|s| match *s {
        "roll" => "sin(roll)".to_string(),
        "pitch" => "sin(pitch)".to_string(),
        s => s.to_string(),
    }));
    t.extend(DEFAULT_INPUTS.iter().map(|s| s.to_string()));
    t.extend(PHYSICS_STATES.iter().map(|s| format!("{s}^2")));
    for s in PHYSICS_STATES {
        for u in DEFAULT_INPUTS {
            t.push(format!("{s}*{u}"));
        }
    }
    for s in ["cos(roll)", "cos(pitch)", "cos(roll)*cos(pitch)"] {
        t.push(s.to_string());
    }
    t
}

type Monomial = BTreeMap<Base, u32>;
type Poly = BTreeMap<Monomial, f64>;

fn mono(factors: &[(Base, u32)]) -> Monomial {
    factors.iter().copied().collect()
}

fn mul(a: &Poly, b: &Poly) -> Poly {
    let mut out = Poly::new();
    for (ma, ca) in a {
        for (mb, cb) in b {
            let mut m = ma.clone();
            for (base, p) in mb {
                *m.entry(*base).or_insert(0) += p;
            }
            *out.entry(m).or_insert(0.0) += ca * cb;
        }
    }
    out
}

/// sin(yaw)^a with a ≥ 2 rewritten as sin(yaw)^(a−2)·(1 − cos(yaw)^2), until no power ≥ 2 is left:
/// one canonical form per trigonometric polynomial of the heading.
fn reduce(p: Poly) -> Poly {
    let mut out = Poly::new();
    let mut todo: Vec<(Monomial, f64)> = p.into_iter().collect();
    while let Some((m, c)) = todo.pop() {
        let s = m.get(&Base::Sin(YAW)).copied().unwrap_or(0);
        if s < 2 {
            *out.entry(m).or_insert(0.0) += c;
            continue;
        }
        let mut lower = m.clone();
        if s == 2 {
            lower.remove(&Base::Sin(YAW));
        } else {
            lower.insert(Base::Sin(YAW), s - 2);
        }
        let mut with_cos = lower.clone();
        *with_cos.entry(Base::Cos(YAW)).or_insert(0) += 2;
        todo.push((lower, c));
        todo.push((with_cos, -c));
    }
    out.retain(|_, c| *c != 0.0);
    out
}

/// `term` (over heading-frame variables) times `rot` (cos ψ or sin ψ), in world variables.
fn expand(term: &Term, rot: Base) -> Poly {
    let one = |factors: &[(Base, u32)], c: f64| -> Poly { [(mono(factors), c)].into_iter().collect() };
    let (c, s) = (Base::Cos(YAW), Base::Sin(YAW));
    let mut p = one(&[(rot, 1)], 1.0);
    for &(base, power) in &term.factors {
        let f: Poly = match base {
            Base::Var(VX) => [
                (mono(&[(Base::Var(VX), 1), (c, 1)]), 1.0),
                (mono(&[(Base::Var(VY), 1), (s, 1)]), 1.0),
            ]
            .into_iter()
            .collect(),
            Base::Var(VY) => [
                (mono(&[(Base::Var(VX), 1), (s, 1)]), -1.0),
                (mono(&[(Base::Var(VY), 1), (c, 1)]), 1.0),
            ]
            .into_iter()
            .collect(),
            b => one(&[(b, 1)], 1.0),
        };
        for _ in 0..power {
            p = mul(&p, &f);
        }
    }
    reduce(p)
}

fn to_term(m: &Monomial) -> Term {
    Term {
        factors: m.iter().map(|(b, p)| (*b, *p)).collect(),
    }
}

/// The joint design of the vx and vy rows over the heading-frame library, and the map of its
/// coefficients to world-frame terms.
#[derive(Clone, Debug)]
pub struct PairDesign {
    /// Θ_h without the terms of `excluded` variables.
    pub library: Library,
    /// Every world term the expansion produces, in first-appearance order.
    pub world_terms: Vec<Term>,
    /// For each of the 2p joint coefficients (ξ_f then ξ_l): its contributions (world term index,
    /// factor) to the vx row and to the vy row.
    map: Vec<[Vec<(usize, f64)>; 2]>,
}

impl PairDesign {
    /// The design over `vars` (the 16 states then inputs) without the terms that use an `excluded`
    /// variable (yaw never appears in Θ_h).
    pub fn new(excluded: &[usize], vars: &[String]) -> Self {
        let full = Library::new(heading_frame_library(), vars).expect("the heading-frame library parses");
        let keep: Vec<usize> = (0..full.len())
            .filter(|&j| {
                !full.terms[j].factors.iter().any(|(b, _)| match b {
                    Base::Var(v) | Base::Sin(v) | Base::Cos(v) => *v != YAW && excluded.contains(v),
                })
            })
            .collect();
        let library = Library {
            names: keep.iter().map(|&j| full.names[j].clone()).collect(),
            terms: keep.iter().map(|&j| full.terms[j].clone()).collect(),
        };
        let mut world_terms: Vec<Term> = Vec::new();
        let index = |t: Term, world_terms: &mut Vec<Term>| -> usize {
            match world_terms.iter().position(|w| *w == t) {
                Some(i) => i,
                None => {
                    world_terms.push(t);
                    world_terms.len() - 1
                }
            }
        };
        let list = |p: &Poly, sign: f64, world_terms: &mut Vec<Term>| -> Vec<(usize, f64)> {
            p.iter()
                .map(|(m, c)| (index(to_term(m), world_terms), sign * c))
                .collect()
        };
        let p = library.len();
        let mut map = vec![[Vec::new(), Vec::new()]; 2 * p];
        for (j, term) in library.terms.iter().enumerate() {
            let ec = expand(term, Base::Cos(YAW));
            let es = expand(term, Base::Sin(YAW));
            // ξ_f: vx += cos ψ θ, vy += sin ψ θ; ξ_l: vx −= sin ψ θ, vy += cos ψ θ.
            map[j] = [list(&ec, 1.0, &mut world_terms), list(&es, 1.0, &mut world_terms)];
            map[p + j] = [list(&es, -1.0, &mut world_terms), list(&ec, 1.0, &mut world_terms)];
        }
        Self {
            library,
            world_terms,
            map,
        }
    }

    /// Number of joint coefficients (2 × the heading-frame terms).
    pub fn columns(&self) -> usize {
        2 * self.library.len()
    }

    /// The design rows of the vx and vy equations at one sample `v` (16 values; 2p each).
    pub fn rows(&self, v: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (s, c) = v[YAW].sin_cos();
        let mut h = v.to_vec();
        h[VX] = c * v[VX] + s * v[VY];
        h[VY] = -s * v[VX] + c * v[VY];
        let p = self.library.len();
        let (mut top, mut bottom) = (vec![0.0; 2 * p], vec![0.0; 2 * p]);
        for (j, t) in self.library.terms.iter().enumerate() {
            let th = eval_term(t, &h);
            top[j] = c * th;
            bottom[j] = s * th;
            top[p + j] = -s * th;
            bottom[p + j] = c * th;
        }
        (top, bottom)
    }

    /// The world-frame coefficients of the vx and vy rows (one value per [`Self::world_terms`]) of
    /// the joint coefficients `xi` (2p). Sums that cancel to within 1e-12 of the row's largest
    /// coefficient are set to 0.
    pub fn world_rows(&self, xi: &[f64]) -> [Vec<f64>; 2] {
        let mut rows = [vec![0.0; self.world_terms.len()], vec![0.0; self.world_terms.len()]];
        for (k, &x) in xi.iter().enumerate() {
            if x == 0.0 {
                continue;
            }
            for (r, row) in rows.iter_mut().enumerate() {
                for &(i, f) in &self.map[k][r] {
                    row[i] += x * f;
                }
            }
        }
        for row in rows.iter_mut() {
            let big = row.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            for v in row.iter_mut() {
                if v.abs() <= 1e-12 * big {
                    *v = 0.0;
                }
            }
        }
        rows
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::DEFAULT_STATES;

    fn vars() -> Vec<String> {
        DEFAULT_STATES
            .iter()
            .chain(DEFAULT_INPUTS.iter())
            .map(|s| s.to_string())
            .collect()
    }

    #[test]
    fn tiny_expansions_by_hand() {
        let vars = vars();
        let t = |s: &str| crate::model::parse_term(s, &vars).unwrap();
        // v_f · cos ψ = vx cos² ψ + vy sin ψ cos ψ.
        let e = expand(&t("vx"), Base::Cos(YAW));
        let names: BTreeMap<String, f64> = e.iter().map(|(m, c)| (to_term(m).display(&vars), *c)).collect();
        assert_eq!(names.len(), 2, "{names:?}");
        assert_eq!(names["vx*cos(yaw)^2"], 1.0);
        assert_eq!(names["vy*sin(yaw)*cos(yaw)"], 1.0);
        // v_l · sin ψ = −vx sin² ψ + vy sin ψ cos ψ = −vx + vx cos² ψ + vy sin ψ cos ψ.
        let e = expand(&t("vy"), Base::Sin(YAW));
        let names: BTreeMap<String, f64> = e.iter().map(|(m, c)| (to_term(m).display(&vars), *c)).collect();
        assert_eq!(names.len(), 3, "{names:?}");
        assert_eq!(names["vx"], -1.0);
        assert_eq!(names["vx*cos(yaw)^2"], 1.0);
        // A term without velocity is only rotated: u_roll · sin ψ.
        let e = expand(&t("u_roll"), Base::Sin(YAW));
        assert_eq!(e.len(), 1);
        assert_eq!(to_term(e.keys().next().unwrap()).display(&vars), "u_roll*sin(yaw)");
    }

    #[test]
    fn isotropic_drag_is_heading_free() {
        // ξ_f = ξ_l = −k on v_f, v_l: the world rows are −k vx and −k vy.
        let vars = vars();
        let d = PairDesign::new(&[], &vars);
        let p = d.library.len();
        let j = d.library.names.iter().position(|n| n == "vx").unwrap();
        let jl = d.library.names.iter().position(|n| n == "vy").unwrap();
        let mut xi = vec![0.0; 2 * p];
        xi[j] = -0.3;
        xi[p + jl] = -0.3;
        let [rx, ry] = d.world_rows(&xi);
        let nz = |r: &Vec<f64>| -> Vec<(String, f64)> {
            r.iter()
                .enumerate()
                .filter(|(_, c)| **c != 0.0)
                .map(|(i, c)| (d.world_terms[i].display(&vars), *c))
                .collect()
        };
        assert_eq!(nz(&rx), vec![("vx".to_string(), -0.3)]);
        assert_eq!(nz(&ry), vec![("vy".to_string(), -0.3)]);
    }

    #[test]
    fn world_rows_equal_rotated_heading_frame_rows() {
        // Property: for random joint coefficients and states, the world rows evaluated on the world
        // terms equal the design rows times ξ (the rotated heading-frame rows), at any heading.
        let vars = vars();
        let d = PairDesign::new(&[15], &vars);
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..20 {
            let xi: Vec<f64> = (0..d.columns())
                .map(|_| if rnd() > 0.3 { rnd() } else { 0.0 })
                .collect();
            let [rx, ry] = d.world_rows(&xi);
            for _ in 0..5 {
                let mut v: Vec<f64> = (0..16).map(|_| rnd()).collect();
                v[YAW] = 4.0 * rnd();
                let (top, bottom) = d.rows(&v);
                let want_x: f64 = top.iter().zip(&xi).map(|(a, b)| a * b).sum();
                let want_y: f64 = bottom.iter().zip(&xi).map(|(a, b)| a * b).sum();
                let got =
                    |r: &Vec<f64>| -> f64 { d.world_terms.iter().zip(r).map(|(t, c)| c * eval_term(t, &v)).sum() };
                assert!((got(&rx) - want_x).abs() < 1e-9, "{} vs {want_x}", got(&rx));
                assert!((got(&ry) - want_y).abs() < 1e-9, "{} vs {want_y}", got(&ry));
            }
        }
    }

    #[test]
    fn silent_inputs_leave_the_library() {
        let d = PairDesign::new(&[YAW, 15], &vars());
        assert_eq!(heading_frame_library().len(), 56);
        assert_eq!(d.library.len(), 56 - 9);
        assert!(d.library.terms.iter().all(|t| t.variables().all(|v| v != YAW)));
    }
}
