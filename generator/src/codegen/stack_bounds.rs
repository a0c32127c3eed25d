//! Measured stack bounds of the checked-in generated crates, quoted in a crate's README and C
//! header (docs/generated-api.md, "Stack").
//!
//! The figures come from `generated/stack-bounds.json`, written by `scripts/stack_bounds.sh
//! --update` (thumbv7em-none-eabihf, cortex-m7, release; a call-graph bound of every Rust API and
//! C ABI function) and checked by it in CI: a bound over its limit fails. The generator quotes the
//! limits (the figures CI guarantees), and only for a crate of the same name generated with the
//! same model and options lines (`generated_with`); any other crate gets a note on how to measure.

use serde_json::Value;

/// The table, compiled in.
const TABLE: &str = include_str!("../../../generated/stack-bounds.json");

/// One crate's limits in bytes: `(function, limit)`, by API.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct StackBounds {
    /// The Rust API (`Mpc::prepare`, …, `discrete_dynamics`).
    pub rust: Vec<(String, u64)>,
    /// The C ABI (`<name>_init`, …), if measured.
    pub c: Vec<(String, u64)>,
    /// The measurement's target and command.
    pub target: String,
}

fn limits(value: Option<&Value>) -> Vec<(String, u64)> {
    let Some(map) = value.and_then(Value::as_object) else {
        return Vec::new();
    };
    map.iter()
        .filter_map(|(f, v)| Some((f.clone(), v.get("limit")?.as_u64()?)))
        .collect()
}

/// The limits of `crate_name` if the table measured a crate generated with these `model:` and
/// `options:` header lines (`header` is the generated crate's header, `header::lines`).
pub fn lookup(crate_name: &str, header: &[String]) -> Option<StackBounds> {
    let table: Value = serde_json::from_str(TABLE).ok()?;
    let entry = table.get("crates")?.get(crate_name)?;
    let with: Vec<&str> = entry
        .get("generated_with")?
        .as_array()?
        .iter()
        .filter_map(Value::as_str)
        .collect();
    let ours: Vec<&str> = header
        .iter()
        .map(String::as_str)
        .filter(|l| l.starts_with("model:") || l.starts_with("options:"))
        .collect();
    if with != ours {
        return None;
    }
    Some(StackBounds {
        rust: limits(entry.get("rust")),
        c: limits(entry.get("c")),
        target: table.get("target").and_then(Value::as_str).unwrap_or("").to_string(),
    })
}

/// The README section.
pub fn readme_section(crate_name: &str, header: &[String]) -> String {
    let mut s = String::from("\n## Stack\n\n");
    match lookup(crate_name, header) {
        Some(b) => {
            s.push_str(&format!(
                "Worst-case stack of each function in bytes on {}: a call-graph bound, checked by uavgen's\n\
                 CI (`scripts/stack_bounds.sh` fails when a bound grows past these limits). Interrupts that\n\
                 preempt a call add their own frames. The solver itself lives in caller storage (a `static`).\n\n\
                 | function | stack ≤ B |\n|---|---:|\n",
                b.target
            ));
            for (f, l) in &b.rust {
                let name = if f == "discrete_dynamics" {
                    f.clone()
                } else if f == "new" {
                    "`*m = const { Mpc::new() }`".to_string()
                } else {
                    format!("Mpc::{f}")
                };
                let name = if name.starts_with('`') {
                    name
                } else {
                    format!("`{name}`")
                };
                s.push_str(&format!("| {name} | {l} |\n"));
            }
            let p = super::c_api::prefix(crate_name);
            for (f, l) in &b.c {
                s.push_str(&format!("| `{p}_{f}` (C) | {l} |\n"));
            }
            s.push_str(
                "\nA `Mpc::new()` evaluated at run time may build the solver in its caller's frame first:\n\
                 initialise a `static` (evaluated at compile time) or assign `const { Mpc::new() }`.\n",
            );
        }
        None => s.push_str(
            "Not measured for this crate. uavgen's `scripts/stack_bounds.sh` bounds the checked-in crates'\n\
             functions on thumbv7em (docs/generated-api.md, \"Stack\"); the figures grow with NX, NU and N.\n",
        ),
    }
    s
}

/// The C header's `#define <NAME>_STACK_<FUNCTION>` lines (or a note when not measured).
pub fn header_defines(crate_name: &str, header: &[String]) -> String {
    let p = super::c_api::prefix(crate_name);
    let up = p.to_ascii_uppercase();
    match lookup(crate_name, header) {
        Some(b) if !b.c.is_empty() => {
            let mut s = format!(
                "/* Stack: worst-case bytes each function needs on {}, a call-graph\n \
                 * bound checked by uavgen's CI (scripts/stack_bounds.sh fails when a bound grows past these).\n \
                 * Size a task's stack as the largest it calls plus the task's own frames and the interrupt\n \
                 * frames that can preempt it. */\n",
                b.target
            );
            for (f, l) in &b.c {
                s.push_str(&format!("#define {up}_STACK_{} {l}\n", f.to_ascii_uppercase()));
            }
            s
        }
        _ => "/* Stack: not measured for this crate (uavgen's scripts/stack_bounds.sh bounds the checked-in\n \
              * crates' functions on thumbv7em; see docs/generated-api.md, \"Stack\"). */\n"
            .to_string(),
    }
}
