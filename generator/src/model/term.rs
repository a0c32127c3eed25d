//! SINDy library terms: grammar, canonical form and symbolic construction.
//!
//! ```text
//! term    := "1" | factor (sep factor)*        sep := "*" | whitespace
//! factor  := atom ("^" integer≥1)?
//! atom    := variable | ("sin" | "cos") "(" variable ")"
//! ```
//! PySINDy's space-separated products (`vx sin(roll)`) and `*` products
//! (`vx*sin(roll)`) parse to the same canonical term.

use crate::symbolic::{Graph, Id};
use std::fmt;

/// Largest power of one factor.
pub const MAX_POWER: u32 = 16;

/// The base of one factor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Base {
    Var(usize),
    Sin(usize),
    Cos(usize),
}

/// A product of powers of bases; the empty product is the constant term `1`.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Term {
    /// Sorted by base, each base once, powers ≥ 1.
    pub factors: Vec<(Base, u32)>,
}

/// Why a term string was rejected.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TermError {
    Syntax(String),
    UnknownVariable(String),
}

impl fmt::Display for TermError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TermError::Syntax(m) => write!(f, "bad term syntax: {m}"),
            TermError::UnknownVariable(v) => write!(f, "unknown variable '{v}'"),
        }
    }
}

struct Lexer<'a> {
    s: &'a str,
    pos: usize,
}

impl<'a> Lexer<'a> {
    fn skip_ws(&mut self) -> bool {
        let start = self.pos;
        while self.peek().is_some_and(|c| c.is_whitespace()) {
            self.pos += 1;
        }
        self.pos > start
    }
    fn peek(&self) -> Option<char> {
        self.s[self.pos..].chars().next()
    }
    fn eat(&mut self, c: char) -> bool {
        if self.peek() == Some(c) {
            self.pos += c.len_utf8();
            true
        } else {
            false
        }
    }
    fn ident(&mut self) -> Option<&'a str> {
        let start = self.pos;
        let rest = &self.s[start..];
        let first = rest.chars().next()?;
        if !(first.is_ascii_alphabetic() || first == '_') {
            return None;
        }
        let len = rest
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(rest.len());
        self.pos += len;
        Some(&rest[..len])
    }
    fn integer(&mut self) -> Option<&'a str> {
        let rest = &self.s[self.pos..];
        let len = rest.find(|c: char| !c.is_ascii_digit()).unwrap_or(rest.len());
        if len == 0 {
            return None;
        }
        self.pos += len;
        Some(&rest[..len])
    }
}

/// Parse `text` with variables named `vars` (states then inputs).
pub fn parse_term(text: &str, vars: &[String]) -> Result<Term, TermError> {
    let syntax = |m: String| TermError::Syntax(m);
    let trimmed = text.trim();
    if trimmed.is_empty() {
        return Err(syntax("empty term".into()));
    }
    if trimmed == "1" {
        return Ok(Term { factors: Vec::new() });
    }
    let lookup = |name: &str| {
        vars.iter()
            .position(|v| v == name)
            .ok_or_else(|| TermError::UnknownVariable(name.to_owned()))
    };
    let mut lx = Lexer { s: trimmed, pos: 0 };
    let mut factors: Vec<(Base, u32)> = Vec::new();
    loop {
        let at = lx.pos;
        let name = lx
            .ident()
            .ok_or_else(|| syntax(format!("expected a variable, sin(..) or cos(..) at column {}", at + 1)))?;
        let base = match name {
            "sin" | "cos" => {
                lx.skip_ws();
                if !lx.eat('(') {
                    return Err(syntax(format!("expected '(' after '{name}'")));
                }
                lx.skip_ws();
                let arg = lx
                    .ident()
                    .ok_or_else(|| syntax(format!("{name}(..) takes a variable name")))?;
                lx.skip_ws();
                if !lx.eat(')') {
                    return Err(syntax(format!("expected ')' after {name}({arg}")));
                }
                let v = lookup(arg)?;
                if name == "sin" {
                    Base::Sin(v)
                } else {
                    Base::Cos(v)
                }
            }
            _ => Base::Var(lookup(name)?),
        };
        let mut had_ws = lx.skip_ws();
        let mut power = 1;
        if lx.eat('^') {
            lx.skip_ws();
            let digits = lx
                .integer()
                .ok_or_else(|| syntax("expected a positive integer power after '^'".into()))?;
            power = digits
                .parse::<u32>()
                .ok()
                .filter(|&p| (1..=MAX_POWER).contains(&p))
                .ok_or_else(|| syntax(format!("power {digits} out of range 1..={MAX_POWER}")))?;
            // The separator after a factor is what follows its power.
            had_ws = false;
        }
        match factors.iter_mut().find(|(b, _)| *b == base) {
            Some((_, p)) => *p += power,
            None => factors.push((base, power)),
        }
        if factors.iter().any(|&(_, p)| p > MAX_POWER) {
            return Err(syntax(format!("combined power of a factor exceeds {MAX_POWER}")));
        }
        had_ws |= lx.skip_ws();
        if lx.pos == trimmed.len() {
            break;
        }
        if lx.eat('*') {
            lx.skip_ws();
        } else if !had_ws {
            return Err(syntax(format!(
                "unexpected '{}' at column {}",
                lx.peek().unwrap_or(' '),
                lx.pos + 1
            )));
        }
    }
    factors.sort();
    Ok(Term { factors })
}

impl Term {
    /// Canonical text (`*`-separated, sorted) using `vars` for names.
    pub fn display(&self, vars: &[String]) -> String {
        if self.factors.is_empty() {
            return "1".into();
        }
        let parts: Vec<String> = self
            .factors
            .iter()
            .map(|&(b, p)| {
                let base = match b {
                    Base::Var(v) => vars[v].clone(),
                    Base::Sin(v) => format!("sin({})", vars[v]),
                    Base::Cos(v) => format!("cos({})", vars[v]),
                };
                if p == 1 {
                    base
                } else {
                    format!("{base}^{p}")
                }
            })
            .collect();
        parts.join("*")
    }

    /// Variables this term depends on.
    pub fn variables(&self) -> impl Iterator<Item = usize> + '_ {
        self.factors.iter().map(|&(b, _)| match b {
            Base::Var(v) | Base::Sin(v) | Base::Cos(v) => v,
        })
    }

    /// Build θ(x, u) in the graph; `var_ids[i]` is graph variable i.
    pub fn build(&self, g: &mut Graph, var_ids: &[Id]) -> Id {
        let mut factors = Vec::with_capacity(self.factors.len());
        for &(base, power) in &self.factors {
            let b = match base {
                Base::Var(v) => var_ids[v],
                Base::Sin(v) => g.sin(var_ids[v]),
                Base::Cos(v) => g.cos(var_ids[v]),
            };
            factors.push(g.powi(b, power as i32));
        }
        g.product(factors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vars() -> Vec<String> {
        ["vx", "roll", "u_vz"].iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn star_and_space_products_agree() {
        let v = vars();
        let a = parse_term("vx*sin(roll)", &v).unwrap();
        let b = parse_term("vx sin(roll)", &v).unwrap();
        let c = parse_term("sin( roll ) * vx", &v).unwrap();
        assert_eq!(a, b);
        assert_eq!(a, c);
        assert_eq!(a.display(&v), "vx*sin(roll)");
    }

    #[test]
    fn powers_merge() {
        let v = vars();
        assert_eq!(parse_term("vx vx", &v).unwrap(), parse_term("vx^2", &v).unwrap());
        assert_eq!(parse_term("vx^2 u_vz", &v).unwrap().display(&v), "vx^2*u_vz");
        assert_eq!(parse_term("u_vz vx", &v).unwrap(), parse_term("vx*u_vz", &v).unwrap());
        assert_eq!(parse_term("1", &v).unwrap().factors.len(), 0);
    }

    #[test]
    fn errors_name_the_problem() {
        let v = vars();
        assert_eq!(parse_term("vy", &v), Err(TermError::UnknownVariable("vy".into())));
        assert_eq!(parse_term("sin(vw)", &v), Err(TermError::UnknownVariable("vw".into())));
        for bad in [
            "", "vx^", "vx^0", "vx**2", "sin vx", "sin(vx", "2*vx", "vx+roll", "tan(vx)x",
        ] {
            assert!(parse_term(bad, &v).is_err(), "'{bad}' must be rejected");
        }
        // Only sin and cos are functions: `tan` reads as an (unknown) variable.
        assert_eq!(parse_term("tan(vx)", &v), Err(TermError::UnknownVariable("tan".into())));
    }
}
