//! Code generation: model → one `TokenStream` per module → prettyplease →
//! files of a `no_std` crate.

pub mod c_api;
pub mod header;
pub mod kernels;
mod lib_rs;
mod manifest;
pub mod model_rs;
pub mod splice;
pub mod stack_bounds;
pub mod write;

use crate::discretize::{auto_substeps, Envelope, SubstepChoice, SubstepError};
use crate::ir::ModelIr;
use crate::model::Model;
use crate::mpc_options::MpcOptions;
use proc_macro2::TokenStream;
use std::path::PathBuf;

pub use crate::symbolic::Float;

/// Everything that shapes a generated crate besides the model.
#[derive(Clone, Debug)]
pub struct GenerateOptions {
    /// MPC horizon N (samples).
    pub horizon: usize,
    /// Sample rate in Hz (DT = 1/rate).
    pub rate_hz: f64,
    /// RK4 substeps per sample; `None` chooses them automatically.
    pub substeps: Option<usize>,
    pub float: Float,
    /// Crate name; default: the model name made into a Rust identifier.
    pub crate_name: Option<String>,
    /// Operating envelope for the automatic substep rule.
    pub envelope: Envelope,
    /// MPC weights, bounds and limits; `None`: `MpcOptions::defaults` for the model.
    pub mpc: Option<MpcOptions>,
    /// Also emit the C ABI: `include/<name>.h` and the `capi/` staticlib package (docs/c-api.md).
    pub c_api: bool,
    /// Which QP solver the crate carries (`--qp`).
    pub qp: QpChoice,
}

/// `--qp`: the QP solver of a generated crate, or `Auto` for the rule of [`QpChoice::resolve`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum QpChoice {
    #[default]
    Auto,
    Condensed,
    Riccati,
}

/// The QP solver a generated crate carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum QpMethod {
    /// Condensed dense box QP in the N·NU inputs, primal active set (templates/src/qp.rs, mpc.rs).
    Condensed,
    /// Stage-wise primal-dual interior point with a Riccati recursion (templates/src/riccati.rs,
    /// mpc_riccati.rs).
    Riccati,
}

impl QpMethod {
    pub fn name(self) -> &'static str {
        match self {
            QpMethod::Condensed => "condensed",
            QpMethod::Riccati => "riccati",
        }
    }
}

impl QpChoice {
    /// The solver for a problem of `nx` states, `nu` inputs (`rate_inputs` of them with an
    /// input-rate weight) and horizon `n`. `Auto` compares the flops of a typical step's QP work
    /// (docs/mpc.md, "Choosing the QP solver"): condensed, condensing N²/2·NU·NX² plus the
    /// Cholesky of the N·NU Hessian (N·NU)³/6 multiply-adds (the rate term only adds to H's
    /// diagonal and first off-diagonal blocks: O(N·NU), not counted); riccati,
    /// `RICCATI_ITERATIONS` Riccati factorisations of N·(2 NX³ + 3 NX² NU) each, plus
    /// N·rate_inputs·(NX² + NX·NU + NU²) for the rate term's blocks. The cheaper one is chosen (the
    /// condensed one on a tie).
    pub fn resolve(self, nx: usize, nu: usize, rate_inputs: usize, n: usize) -> QpMethod {
        self.resolve_for(&kernels::Structure::dense(nx, nu), rate_inputs, n)
    }

    /// [`Self::resolve`] with the condensed solver's cost counted on the emitted kernels of a
    /// model's structure ([`structured_qp_flops`]).
    pub fn resolve_for(self, structure: &kernels::Structure, rate_inputs: usize, n: usize) -> QpMethod {
        match self {
            QpChoice::Condensed => QpMethod::Condensed,
            QpChoice::Riccati => QpMethod::Riccati,
            QpChoice::Auto => {
                let (condensed, riccati) = structured_qp_flops(structure, rate_inputs, n);
                if riccati < condensed {
                    QpMethod::Riccati
                } else {
                    QpMethod::Condensed
                }
            }
        }
    }
}

/// Multiply-adds of a typical step's QP work, (condensed, riccati), for the `--qp auto` rule
/// ([`QpChoice::resolve`]); `rate_inputs` inputs have an input-rate weight.
pub fn qp_flops(nx: usize, nu: usize, rate_inputs: usize, n: usize) -> (f64, f64) {
    let (nx, nu, nr, n) = (nx as f64, nu as f64, rate_inputs as f64, n as f64);
    let nv = n * nu;
    let condensed = n * n / 2.0 * nu * nx * nx + nv * nv * nv / 6.0;
    // The rate term's blocks per stage and rate-weighted input: a row of Pwx A and of Pwx B, a
    // solve with the stage factor for Pww.
    let rate = nr * (nx * nx + nx * nu + nu * nu);
    let riccati = RICCATI_ITERATIONS * n * (2.0 * nx * nx * nx + 3.0 * nx * nx * nu + rate);
    (condensed, riccati)
}

/// [`qp_flops`] with the condensed solver's work counted as the emitted code does it: the
/// condensing kernels over the structural non-zeros and the Cholesky of H over its decoupled input
/// components ([`kernels::Structure::flops`]). Riccati: the dense formula (its kernels are not
/// specialised). With no structural zeros this is [`qp_flops`] up to the condensing's lower-order
/// terms.
pub fn structured_qp_flops(structure: &kernels::Structure, rate_inputs: usize, n: usize) -> (f64, f64) {
    let (_, riccati) = qp_flops(structure.nx, structure.nu, rate_inputs, n);
    let f = structure.flops(n);
    ((f.condensing + f.cholesky) as f64, riccati)
}

/// Interior-point iterations of a typical step, for the `--qp auto` rule (about the median
/// measured on the shipped models, docs/benchmarks.md).
const RICCATI_ITERATIONS: f64 = 10.0;

impl Default for GenerateOptions {
    fn default() -> Self {
        Self {
            horizon: 30,
            rate_hz: 30.0,
            substeps: None,
            float: Float::F64,
            crate_name: None,
            envelope: Envelope::default(),
            mpc: None,
            c_api: false,
            qp: QpChoice::Auto,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    #[error("--{option}: {message}")]
    InvalidOption { option: &'static str, message: String },
    #[error("choosing the substep count: {0}")]
    Substeps(#[from] SubstepError),
    #[error("template: {0}")]
    Template(String),
    #[error("{0}")]
    Constant(#[from] crate::symbolic::NonFiniteConstant),
    #[error("the model grows by e^{per_sample:.3} per sample somewhere in the envelope (eigenvalue {re:.4e}{im:+.4e}i 1/s of ∂f/∂x): no vehicle's dynamics diverge that fast; check its coefficients (at most e^{} per sample is accepted; docs/discretisation.md)", crate::validate::MAX_GROWTH_PER_SAMPLE)]
    Unstable { re: f64, im: f64, per_sample: f64 },
}

/// The files of a generated crate, in memory.
pub struct GeneratedCrate {
    pub crate_name: String,
    pub substeps: usize,
    pub substep_choice: Option<SubstepChoice>,
    pub files: Vec<(PathBuf, String)>,
    /// The QP solver the crate carries.
    pub qp: QpMethod,
    /// Structural patterns of its stage matrices (the emitted `kernels.rs` of a condensed crate).
    pub structure: kernels::Structure,
    /// Multiply-adds of the emitted sensitivity kernels (linearisation).
    pub sensitivity_flops: model_rs::SensitivityFlops,
}

fn invalid(option: &'static str, message: impl Into<String>) -> GenerateError {
    GenerateError::InvalidOption {
        option,
        message: message.into(),
    }
}

/// The model name as a crate name: lowercase `[a-z0-9_]`, not starting with a digit.
pub fn default_crate_name(model_name: &str) -> String {
    let mut s: String = model_name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s.starts_with(|c: char| c.is_ascii_digit()) {
        s.insert_str(0, "model_");
    }
    s
}

impl GenerateOptions {
    pub fn validate(&self) -> Result<(), GenerateError> {
        if !(1..=1000).contains(&self.horizon) {
            return Err(invalid(
                "horizon",
                format!("must be between 1 and 1000 samples, got {}", self.horizon),
            ));
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 100_000.0) {
            return Err(invalid(
                "rate",
                format!(
                    "must be a positive sample rate in Hz (at most 100000), got {}",
                    self.rate_hz
                ),
            ));
        }
        if let Some(m) = self.substeps {
            if !(1..=10_000).contains(&m) {
                return Err(invalid("substeps", format!("must be between 1 and 10000, got {m}")));
            }
        }
        if let Some(name) = &self.crate_name {
            let ok = name.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
                && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
            if !ok {
                return Err(invalid("crate-name", format!("'{name}' is not a valid crate name")));
            }
        }
        Ok(())
    }
}

fn format_file(tokens: TokenStream, what: &str) -> Result<String, GenerateError> {
    let file: syn::File = syn::parse2(tokens)
        .map_err(|e| GenerateError::Template(format!("{what}: emitted tokens do not parse: {e}")))?;
    Ok(prettyplease::unparse(&file))
}

/// Generate the crate for `model` in memory (nothing is written).
pub fn generate(model: &Model, options: &GenerateOptions) -> Result<GeneratedCrate, GenerateError> {
    options.validate()?;
    let ir = ModelIr::new(model);
    let dt = 1.0 / options.rate_hz;
    let (substeps, substep_choice) = match options.substeps {
        Some(m) => (m, None),
        None => {
            let choice = auto_substeps(&ir, dt, &options.envelope)?;
            // The rule imposes nothing for unstable modes; an absurd growth rate is an error.
            let per_sample = choice.fastest_growth.re * dt;
            if per_sample > crate::validate::MAX_GROWTH_PER_SAMPLE {
                return Err(GenerateError::Unstable {
                    re: choice.fastest_growth.re,
                    im: choice.fastest_growth.im,
                    per_sample,
                });
            }
            (choice.substeps, Some(choice))
        }
    };
    let crate_name = options
        .crate_name
        .clone()
        .unwrap_or_else(|| default_crate_name(&model.name));
    let mpc = match &options.mpc {
        Some(m) => {
            if m.q.len() != model.nx() || m.q_terminal.len() != model.nx() || m.r.len() != model.nu() {
                return Err(invalid("mpc", "the MPC options were made for a model of other sizes"));
            }
            m.clone()
        }
        None => MpcOptions::defaults(model),
    };
    // Each input's inputs already sent (its lead over the shared delay) are held at the start of
    // the plan: the horizon must reach past them.
    let lead = ir.input_lead(1.0 / options.rate_hz);
    if let Some((j, &l)) = lead.iter().enumerate().max_by_key(|(_, &l)| l) {
        if l >= options.horizon {
            return Err(invalid(
                "horizon",
                format!(
                    "the input {} is delayed {l} samples more than the fastest input; the horizon ({}) must be longer \
                     than that (docs/mpc.md \"Input delays\")",
                    model.inputs[j], options.horizon
                ),
            ));
        }
    }
    let structure = kernels::Structure::from_ir(&ir, substeps, &mpc.q, &mpc.q_terminal);
    // Both solvers carry the input-rate term (the stage-wise one with the previous input step as
    // a state); `auto` counts its cost for the inputs that have one.
    let rate_inputs = mpc.r_delta.iter().filter(|&&s| s != 0.0).count();
    let qp = options.qp.resolve_for(&structure, rate_inputs, options.horizon);
    let head = header::lines(model, options, substeps, &mpc, qp);
    let rs_header = header::rust(&head);

    let dims = splice::specialise_dims(
        options.float.name(),
        &lib_rs::dims_values(
            &ir,
            options,
            substeps,
            &mpc,
            &model.input_delays(),
            model.envelope.as_ref(),
        )?,
    )
    .map_err(GenerateError::Template)?;
    let (model_tokens, used_math, sensitivity_flops) = model_rs::emit(&ir, options.float, &structure.s)?;
    let mut files = vec![
        (
            PathBuf::from("Cargo.toml"),
            format!("{}{}", header::toml(&head), manifest::cargo_toml(&crate_name, model)),
        ),
        (
            PathBuf::from("README.md"),
            manifest::readme(&crate_name, model, options, substeps, &head)
                + &stack_bounds::readme_section(&crate_name, &head),
        ),
        (
            PathBuf::from("src/lib.rs"),
            rs_header.clone() + &format_file(lib_rs::emit(model, &ir, qp), "lib.rs")?,
        ),
        (
            PathBuf::from("src/dims.rs"),
            rs_header.clone() + &prettyplease::unparse(&dims),
        ),
        (
            PathBuf::from("src/model.rs"),
            rs_header.clone() + &format_file(model_tokens, "model.rs")?,
        ),
        (
            PathBuf::from("src/math.rs"),
            rs_header.clone() + &prettyplease::unparse(&splice::math(&used_math)),
        ),
    ];
    let solver = match qp {
        QpMethod::Condensed => [("src/qp.rs", splice::QP_RS), ("src/mpc.rs", splice::MPC_RS)],
        QpMethod::Riccati => [
            ("src/riccati.rs", splice::RICCATI_RS),
            ("src/mpc.rs", splice::MPC_RICCATI_RS),
        ],
    };
    for (name, source) in [("src/rk4.rs", splice::RK4_RS)].into_iter().chain(solver) {
        files.push((
            PathBuf::from(name),
            rs_header.clone() + &prettyplease::unparse(&splice::template(source)),
        ));
    }
    if qp == QpMethod::Condensed {
        files.push((
            PathBuf::from("src/kernels.rs"),
            rs_header.clone() + &format_file(structure.emit(options.horizon), "kernels.rs")?,
        ));
    }
    if options.c_api {
        let api = c_api::CApi {
            crate_name: &crate_name,
            qp,
            model,
            options,
            mpc: &mpc,
            substeps,
            header: &head,
        };
        files.extend(api.files().map_err(GenerateError::Template)?);
    }
    Ok(GeneratedCrate {
        crate_name,
        substeps,
        substep_choice,
        files,
        qp,
        structure,
        sensitivity_flops,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_counts_the_rate_term_and_picks_by_flops() {
        // N = 30, NX = 12, NU = 4 (the shipped sizes): condensed 0.55 M multiply-adds without
        // structural zeros against riccati 10 × 30 × (3456 + 1728) = 1.56 M, + 0.12 M for two
        // rate-weighted inputs; N = 100: the condensed work is cubic in N (13.5 M by this formula),
        // the stage-wise one linear (5.2 M, 5.6 M with the rate term).
        let (condensed, riccati) = qp_flops(12, 4, 0, 30);
        let (_, with_rate) = qp_flops(12, 4, 2, 30);
        assert_eq!(condensed, 30.0 * 30.0 / 2.0 * 4.0 * 144.0 + 120.0f64.powi(3) / 6.0);
        assert_eq!(riccati, 10.0 * 30.0 * (2.0 * 1728.0 + 3.0 * 144.0 * 4.0));
        assert_eq!(with_rate - riccati, 10.0 * 30.0 * 2.0 * (144.0 + 48.0 + 16.0));
        assert_eq!(QpChoice::Auto.resolve(12, 4, 2, 30), QpMethod::Condensed);
        assert_eq!(QpChoice::Auto.resolve(12, 4, 2, 100), QpMethod::Riccati);
        assert_eq!(QpChoice::Auto.resolve(12, 4, 0, 100), QpMethod::Riccati);
        // An explicit choice is kept whatever the rate weights.
        assert_eq!(QpChoice::Riccati.resolve(12, 4, 4, 30), QpMethod::Riccati);
        assert_eq!(QpChoice::Condensed.resolve(12, 4, 0, 100), QpMethod::Condensed);
    }
}
