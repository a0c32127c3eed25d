//! Read the problem constants back from a generated crate's `src/dims.rs`
//! (parsed with syn), so the generic solver solves the crate's exact problem.

use crate::MpcOptions;
use std::collections::HashMap;
use std::path::Path;
use syn::{Expr, Item, Lit, UnOp};

/// Sizes and options of a generated crate.
#[derive(Debug, Clone)]
pub struct CrateDims {
    pub horizon: usize,
    pub dt: f64,
    pub substeps: usize,
    pub options: MpcOptions,
}

fn number(e: &Expr) -> Option<f64> {
    match e {
        Expr::Lit(l) => match &l.lit {
            Lit::Float(f) => f.base10_parse().ok(),
            Lit::Int(i) => i.base10_parse::<f64>().ok(),
            _ => None,
        },
        Expr::Unary(u) if matches!(u.op, UnOp::Neg(_)) => number(&u.expr).map(|v| -v),
        Expr::Paren(p) => number(&p.expr),
        _ => None,
    }
}

fn values(e: &Expr) -> Option<Vec<f64>> {
    match e {
        Expr::Array(a) => a.elems.iter().map(number).collect(),
        _ => number(e).map(|v| vec![v]),
    }
}

/// Parse `crate_dir/src/dims.rs`.
pub fn read(crate_dir: &Path) -> Result<CrateDims, String> {
    let path = crate_dir.join("src/dims.rs");
    let text = std::fs::read_to_string(&path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    let file: syn::File = syn::parse_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut consts: HashMap<String, Vec<f64>> = HashMap::new();
    for item in &file.items {
        if let Item::Const(c) = item {
            if let Some(v) = values(&c.expr) {
                consts.insert(c.ident.to_string(), v);
            }
        }
    }
    let get = |name: &str| {
        consts
            .get(name)
            .cloned()
            .ok_or_else(|| format!("{}: no constant {name}", path.display()))
    };
    let scalar = |name: &str| get(name).map(|v| v[0]);
    Ok(CrateDims {
        horizon: scalar("N")? as usize,
        dt: scalar("DT")?,
        substeps: scalar("SUBSTEPS")? as usize,
        options: MpcOptions {
            q: get("Q")?,
            q_terminal: get("Q_TERMINAL")?,
            r: get("R")?,
            // Crates generated before the input-rate weight have no such constant.
            r_delta: get("R_DELTA").unwrap_or_else(|_| vec![0.0; get("R").map_or(0, |r| r.len())]),
            u_min: get("U_MIN")?,
            u_max: get("U_MAX")?,
            max_qp_iterations: scalar("MAX_QP_ITERATIONS")? as usize,
            // Crates generated before the work budget have no such constant.
            max_qp_work: scalar("MAX_QP_WORK").ok().map(|v| v as usize),
            // Crates generated before the Riccati solver have no such constant.
            max_ipm_iterations: scalar("MAX_IPM_ITERATIONS")
                .map_or(crate::mpc_options::DEFAULT_MAX_IPM_ITERATIONS, |v| v as usize),
            regularisation: scalar("REGULARISATION")?,
            // Crates generated before the disturbance observer have no such constants (gain 0: off).
            disturbance_gain: scalar("DISTURBANCE_GAIN").unwrap_or(0.0),
            disturbance_max_acceleration: match (get("DISTURBANCE_BOUND"), scalar("DT")) {
                (Ok(b), Ok(dt)) if dt > 0.0 => b.iter().copied().fold(0.0, f64::max) / dt,
                _ => 0.0,
            },
            // Recovery does not change the work of a step: the defaults (crates before it have none).
            max_position_error: crate::mpc_options::DEFAULT_MAX_POSITION_ERROR,
            recovery_speed: crate::mpc_options::DEFAULT_RECOVERY_SPEED,
        },
    })
}
