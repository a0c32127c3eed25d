//! Candidate libraries Θ(x, u) as term strings of the model grammar, and their evaluation.

use crate::model::{parse_term, Base, Term, TermError, DEFAULT_INPUTS, DEFAULT_STATES};
use nalgebra::DMatrix;

/// Which candidate library to fit with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LibraryKind {
    /// The paper's Θ = [1, x, u, x², x·u, sin Ω, cos Ω, x sin Ω, x cos Ω] (155 terms, the order of
    /// `models/sindy_m100.json`).
    Paper,
    /// Translation- and heading-invariant candidates (no raw x, y, z, yaw; heading only through
    /// sin(yaw)/cos(yaw) products), 66 terms. See [`physics_library`].
    Physics,
}

impl LibraryKind {
    pub fn name(self) -> &'static str {
        match self {
            LibraryKind::Paper => "paper",
            LibraryKind::Physics => "physics",
        }
    }

    /// The term strings, in library order.
    pub fn terms(self) -> Vec<String> {
        match self {
            LibraryKind::Paper => paper_library(),
            LibraryKind::Physics => physics_library(),
        }
    }
}

const ANGLES: [&str; 3] = ["roll", "pitch", "yaw"];

/// The paper's library, 155 terms:
/// `1`; the 12 states; the 4 inputs; the 12 squares `s^2`; the 48 products `s*u` (state-major);
/// `sin(roll) sin(pitch) sin(yaw) cos(roll) cos(pitch) cos(yaw)`; the 36 `s*sin(a)` (state-major,
/// then angle); the 36 `s*cos(a)`.
pub fn paper_library() -> Vec<String> {
    let mut t = vec!["1".to_string()];
    t.extend(DEFAULT_STATES.iter().map(|s| s.to_string()));
    t.extend(DEFAULT_INPUTS.iter().map(|s| s.to_string()));
    t.extend(DEFAULT_STATES.iter().map(|s| format!("{s}^2")));
    for s in DEFAULT_STATES {
        for u in DEFAULT_INPUTS {
            t.push(format!("{s}*{u}"));
        }
    }
    t.extend(ANGLES.iter().map(|a| format!("sin({a})")));
    t.extend(ANGLES.iter().map(|a| format!("cos({a})")));
    for f in ["sin", "cos"] {
        for s in DEFAULT_STATES {
            for a in ANGLES {
                t.push(format!("{s}*{f}({a})"));
            }
        }
    }
    t
}

/// The states the physics library uses directly: everything but x, y, z and yaw.
pub const PHYSICS_STATES: [&str; 8] = ["roll", "pitch", "vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"];

/// The physics-aware library, 66 terms, in this order:
///
/// - `1`;
/// - the 8 invariant states (roll pitch vx vy vz roll_rate pitch_rate yaw_rate), the 4 inputs;
/// - the 8 squares of those states;
/// - the 32 products invariant state × input (state-major);
/// - `cos(roll) cos(pitch)`, `cos(roll)*cos(pitch)` (vertical thrust component);
/// - heading: `sin(yaw) cos(yaw)` and `a*sin(yaw)`, `a*cos(yaw)` for a in u_roll, u_pitch, sin(roll),
///   sin(pitch) (the world-frame components of body-frame tilts and tilt commands).
///
/// An angle appears either bare (`roll`, in the attitude loops) or as its sine (`sin(roll)*cos(yaw)`,
/// in the thrust direction), never both in one role: `roll` and `sin(roll)` are nearly collinear
/// over the flight envelope, and a fit that keeps both returns large cancelling pairs (26 roll·sin ψ
/// − 16 sin(roll)·sin ψ) whose difference is a spurious cubic outside the data.
///
/// Raw x, y, z and yaw never appear, so the fitted dynamics are invariant under translation, and
/// heading enters only as a rotation of body-frame quantities.
pub fn physics_library() -> Vec<String> {
    let mut t = vec!["1".to_string()];
    t.extend(PHYSICS_STATES.iter().map(|s| s.to_string()));
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
    t.push("sin(yaw)".into());
    t.push("cos(yaw)".into());
    for a in ["u_roll", "u_pitch", "sin(roll)", "sin(pitch)"] {
        t.push(format!("{a}*sin(yaw)"));
        t.push(format!("{a}*cos(yaw)"));
    }
    t
}

/// A parsed library over named variables (states then inputs).
#[derive(Clone, Debug)]
pub struct Library {
    pub names: Vec<String>,
    pub terms: Vec<Term>,
}

impl Library {
    /// Parse every term; `vars` are the states then the inputs.
    pub fn new(names: Vec<String>, vars: &[String]) -> Result<Self, (usize, TermError)> {
        let terms = names
            .iter()
            .enumerate()
            .map(|(i, n)| parse_term(n, vars).map_err(|e| (i, e)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { names, terms })
    }

    pub fn len(&self) -> usize {
        self.terms.len()
    }

    pub fn is_empty(&self) -> bool {
        self.terms.is_empty()
    }

    /// Θ: one row per sample (`values[k]` = states then inputs of sample k), one column per term.
    pub fn matrix<'a>(&self, values: impl ExactSizeIterator<Item = &'a [f64]>) -> DMatrix<f64> {
        let n = values.len();
        let mut m = DMatrix::zeros(n, self.terms.len());
        for (k, v) in values.enumerate() {
            for (j, t) in self.terms.iter().enumerate() {
                m[(k, j)] = eval_term(t, v);
            }
        }
        m
    }
}

/// θ(values) for one term; `values` indexed like the variables the term was parsed with.
pub fn eval_term(term: &Term, values: &[f64]) -> f64 {
    let mut r = 1.0;
    for &(base, power) in &term.factors {
        let b = match base {
            Base::Var(v) => values[v],
            Base::Sin(v) => values[v].sin(),
            Base::Cos(v) => values[v].cos(),
        };
        r *= b.powi(power as i32);
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars() -> Vec<String> {
        DEFAULT_STATES
            .iter()
            .chain(DEFAULT_INPUTS.iter())
            .map(|s| s.to_string())
            .collect()
    }

    #[test]
    fn physics_library_matches_shipped_model() {
        // models/sindy_m100.json is identified with the physics library (scripts/identify_m100.sh).
        let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../models/sindy_m100.json")).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        let lib: Vec<String> = serde_json::from_value(v["library"].clone()).unwrap();
        assert_eq!(physics_library(), lib);
        assert_eq!(lib.len(), 66);
        assert_eq!(paper_library().len(), 155);
    }

    #[test]
    fn physics_library_is_invariant_and_unique() {
        let vars = vars();
        let lib = Library::new(physics_library(), &vars).unwrap();
        assert_eq!(lib.len(), 66);
        let mut seen = std::collections::HashSet::new();
        for t in &lib.terms {
            assert!(seen.insert(t.clone()), "duplicate {}", t.display(&vars));
            for &(b, _) in &t.factors {
                // x, y, z (0..3) never; yaw (5) only inside sin/cos.
                match b {
                    Base::Var(i) => assert!(i > 2 && i != 5, "{}", t.display(&vars)),
                    Base::Sin(i) | Base::Cos(i) => assert!(i > 2),
                }
            }
        }
    }

    #[test]
    fn evaluates_products_powers_and_trig() {
        let vars = vars();
        let t = parse_term("vx^2*sin(roll)*cos(yaw)", &vars).unwrap();
        let mut v = vec![0.0; 16];
        v[6] = 2.0;
        v[3] = 0.3;
        v[5] = 1.1;
        assert!((eval_term(&t, &v) - 4.0 * 0.3f64.sin() * 1.1f64.cos()).abs() < 1e-15);
        assert_eq!(eval_term(&parse_term("1", &vars).unwrap(), &v), 1.0);
    }
}
