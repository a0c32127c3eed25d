//! Splicing the `templates` crate into generated crates.
//!
//! The template sources are compiled into the generator with `include_str!`,
//! parsed with `syn`, stripped of their `#[cfg(test)]` items and specialised:
//! in `dims.rs` the values of the size/option constants and the `Real` type
//! are replaced. A constant the generator does not know, or a value it has
//! no constant for, is an error, so template and generator cannot drift apart.

use proc_macro2::TokenStream;
use quote::ToTokens;
use std::collections::BTreeMap;
use syn::{File, Item};

pub const DIMS_RS: &str = include_str!("../../../templates/src/dims.rs");
pub const MATH_RS: &str = include_str!("../../../templates/src/math.rs");
pub const RK4_RS: &str = include_str!("../../../templates/src/rk4.rs");
pub const QP_RS: &str = include_str!("../../../templates/src/qp.rs");
pub const MPC_RS: &str = include_str!("../../../templates/src/mpc.rs");
pub const RICCATI_RS: &str = include_str!("../../../templates/src/riccati.rs");
pub const MPC_RICCATI_RS: &str = include_str!("../../../templates/src/mpc_riccati.rs");

/// Constants of `dims.rs` defined by expressions of the others (kept as written).
const DERIVED: &[&str] = &["NZ", "NV"];

fn is_cfg_test(attrs: &[syn::Attribute]) -> bool {
    attrs
        .iter()
        .any(|a| a.path().is_ident("cfg") && a.to_token_stream().to_string().contains("test"))
}

/// Parse a template file and drop its `#[cfg(test)]` items.
pub fn template(source: &str) -> File {
    let mut file: File =
        syn::parse_str(source).expect("template sources are valid Rust (checked by the templates crate)");
    file.items.retain(|item| {
        let attrs = match item {
            Item::Mod(m) => &m.attrs,
            Item::Fn(f) => &f.attrs,
            Item::Use(u) => &u.attrs,
            Item::Const(c) => &c.attrs,
            _ => return true,
        };
        !is_cfg_test(attrs)
    });
    file
}

/// Math functions the spliced solver modules call themselves.
const SOLVER_MATH: &[&str] = &["sqrt"];

/// `math.rs` with only the functions in `used` and those the solver needs.
pub fn math(used: &std::collections::BTreeSet<&'static str>) -> File {
    let mut file = template(MATH_RS);
    let mut any = false;
    file.items.retain(|item| match item {
        Item::Fn(f) => {
            let name = f.sig.ident.to_string();
            let keep = used.contains(name.as_str()) || SOLVER_MATH.contains(&name.as_str());
            any |= keep;
            keep
        }
        _ => true,
    });
    if !any {
        // Nothing to import from libm: drop the `use` too.
        file.items.retain(|item| !matches!(item, Item::Use(_)));
    }
    file
}

/// `dims.rs` with `type Real` set to `real` and each constant in `values`
/// given its new value expression.
pub fn specialise_dims(real: &str, values: &BTreeMap<&str, TokenStream>) -> Result<File, String> {
    let mut file = template(DIMS_RS);
    let mut seen = Vec::new();
    for item in &mut file.items {
        match item {
            Item::Type(t) if t.ident == "Real" => {
                *t.ty = syn::parse_str(real).map_err(|e| e.to_string())?;
            }
            Item::Const(c) => {
                let name = c.ident.to_string();
                if let Some(v) = values.get(name.as_str()) {
                    *c.expr = syn::parse2(v.clone()).map_err(|e| format!("value of {name}: {e}"))?;
                    seen.push(name);
                } else if !DERIVED.contains(&name.as_str()) {
                    return Err(format!(
                        "templates/src/dims.rs defines {name}, which the generator does not set"
                    ));
                }
            }
            _ => {}
        }
    }
    for name in values.keys() {
        if !seen.iter().any(|s| s == name) {
            return Err(format!("templates/src/dims.rs has no constant {name}"));
        }
    }
    Ok(file)
}
