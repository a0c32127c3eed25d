//! SINDy identification: ẋ ≈ Ξᵀ Θ(x, u) fitted to a [`Dataset`] with STLSQ or SR3 (PySINDy 2.x
//! definitions), optionally with a sparsity sweep selected by AIC. The result is a `uavgen-model/1`
//! [`SindyFile`] with provenance. See `docs/sindy.md`.

pub mod accumulate;
pub mod heading_frame;
pub mod library;
pub mod optimizer;

pub use heading_frame::HeadingFrame;

pub use library::{eval_term, paper_library, physics_library, Library, LibraryKind, PHYSICS_STATES};
pub use optimizer::{lstsq, regress, Optimizer, OptimizerError, Regression, Regularizer};

use super::dataset::Dataset;
use crate::model::{Base, Coefficient, SindyFile, DEFAULT_INPUTS, DEFAULT_STATES, FORMAT};
use accumulate::{Accumulator, LsData, CHUNK_ROWS};
use nalgebra::DMatrix;
use serde_json::{json, Map, Value};

/// The six rows known exactly: `[state, derivative]`.
pub const KINEMATIC: [(&str, &str); 6] = [
    ("x", "vx"),
    ("y", "vy"),
    ("z", "vz"),
    ("roll", "roll_rate"),
    ("pitch", "pitch_rate"),
    ("yaw", "yaw_rate"),
];

/// The six fitted rows when the kinematic rows are exact.
pub const DYNAMIC_STATES: [&str; 6] = ["vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"];

/// Which state derivatives are regressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FittedRows {
    /// The 6 dynamic rows; x..yaw are kinematic rows (ẋ = vx, …, yaw' = yaw_rate), not fitted.
    Dynamic,
    /// All 12 rows are regressed on Θ, as the paper does; no kinematic rows.
    All,
}

/// How a sweep picks its sparsity parameter.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AicSelection {
    /// Every row takes the sweep value minimising its own AIC_i = N ln(RSS_i/N) + 2 k_i.
    PerRow,
    /// One value for all rows, minimising Σ_i AIC_i.
    Total,
}

/// The information criterion a sweep minimises.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Criterion {
    /// AIC = N ln(RSS/N) + 2k.
    Aic,
    /// BIC = N ln(RSS/N) + k ln N (a stronger penalty; AIC tends to keep spurious terms when the
    /// sweep path offers many candidates).
    Bic,
}

impl Criterion {
    pub fn name(self) -> &'static str {
        match self {
            Criterion::Aic => "AIC",
            Criterion::Bic => "BIC",
        }
    }
}

/// Everything that defines a SINDy fit.
#[derive(Clone, Debug, PartialEq)]
pub struct SindyOptions {
    pub library: LibraryKind,
    pub optimizer: Optimizer,
    /// PySINDy's `normalize_columns`: regress on Θ with unit-2-norm columns, rescale Ξ back.
    pub normalize_columns: bool,
    /// Values of the sparsity parameter (`threshold` for STLSQ, `reg_weight_lam` for SR3) to try;
    /// `None`: fit once with the optimiser's own value.
    pub sweep: Option<Vec<f64>>,
    pub selection: AicSelection,
    /// AIC (default) or BIC.
    pub criterion: Criterion,
    pub rows: FittedRows,
    /// The sample count N the information criteria use (default: [`SampleCount::Effective`]).
    pub sample_count: SampleCount,
    /// Variables (index in the 16 states-then-inputs) the logs did not excite
    /// ([`crate::identify::excitation`]): every library term that uses one is left out of the
    /// regression (coefficient 0) and listed in the provenance (`excluded_unexcited_terms`).
    pub excluded_vars: Vec<usize>,
    /// When the vx and vy rows are fitted in the heading frame and written back rotated
    /// ([`heading_frame`]; physics library and dynamic rows only). Default: [`HeadingFrame::Auto`],
    /// when the heading is among `excluded_vars`.
    pub heading_frame: HeadingFrame,
}

impl SindyOptions {
    /// Are the vx and vy rows fitted in the heading frame ([`heading_frame`])?
    pub fn heading_frame_active(&self) -> bool {
        self.rows == FittedRows::Dynamic
            && self.library == LibraryKind::Physics
            && match self.heading_frame {
                HeadingFrame::Auto => self.excluded_vars.contains(&heading_frame::YAW),
                HeadingFrame::Always => true,
                HeadingFrame::Never => false,
            }
    }
}

/// The N of AIC = N ln(RSS/N) + 2k and BIC = N ln(RSS/N) + k ln N.
///
/// Derivatives from a Savitzky-Golay window, and logs with repeated (sample-and-hold) rows, give
/// residuals that are strongly correlated from one sample to the next: the rows are not N
/// independent observations, and with the raw N every criterion keeps nearly every candidate term.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SampleCount {
    /// N = the number of samples (independent residuals).
    Raw,
    /// N_eff = N / τ, τ = 1 + 2 Σ ρ_k the integrated autocorrelation time of the row's residual under
    /// the densest fit of the sweep (ρ_k summed while positive), the same N_eff for every sweep value
    /// of that row.
    Effective,
}

impl Default for SindyOptions {
    /// Physics library, 6 dynamic rows, STLSQ (threshold 0.05, α = 1e-3, unbiased) on normalised
    /// columns, no sweep, per-row AIC if a sweep is given.
    fn default() -> Self {
        Self {
            library: LibraryKind::Physics,
            optimizer: Optimizer::Stlsq {
                threshold: 0.05,
                alpha: 1e-3,
                max_iter: 20,
                unbias: true,
            },
            normalize_columns: true,
            sweep: None,
            selection: AicSelection::PerRow,
            criterion: Criterion::Aic,
            rows: FittedRows::Dynamic,
            sample_count: SampleCount::Effective,
            excluded_vars: Vec::new(),
            heading_frame: HeadingFrame::Auto,
        }
    }
}

/// Why a fit failed.
#[derive(Debug, thiserror::Error)]
pub enum SindyError {
    #[error("the dataset has no samples")]
    Empty,
    #[error("the dataset has {samples} samples, fewer than the {terms} library terms")]
    TooFewSamples { samples: usize, terms: usize },
    #[error("non-finite value in the data (sample {0})")]
    NonFinite(usize),
    #[error("the sweep is empty")]
    EmptySweep,
    #[error("sweep value {0} is not finite and >= 0")]
    BadSweepValue(f64),
    #[error("model name must not be empty")]
    EmptyName,
    #[error(transparent)]
    Optimizer(#[from] OptimizerError),
}

/// One row's fit quality on the training data (in the units of ẋ).
#[derive(Clone, Debug, PartialEq)]
pub struct RowFit {
    pub state: String,
    /// Non-zero coefficients.
    pub terms: usize,
    pub rss: f64,
    pub rmse: f64,
    /// 1 − RSS / Σ (ẋ − mean ẋ)².
    pub r2: f64,
    /// N ln(max(RSS/N, floor)) + 2 k, floor = 1e-24 · mean(ẋ²).
    pub aic: f64,
    /// Same with the penalty k ln N.
    pub bic: f64,
    /// The sparsity parameter this row's coefficients were fitted with.
    pub sparsity: f64,
    /// The N of the criteria ([`SampleCount`]).
    pub n_ic: f64,
}

/// One sweep value: its regression and per-row scores.
#[derive(Clone, Debug)]
pub struct SweepPoint {
    pub value: f64,
    pub iterations: usize,
    pub converged: bool,
    pub rows: Vec<RowFit>,
    pub total_aic: f64,
    pub total_bic: f64,
}

/// The result of [`fit`].
#[derive(Clone, Debug)]
pub struct SindyFit {
    /// The model, ready to be serialised (`serde_json::to_string_pretty`) and read by `model::parse`.
    pub file: SindyFile,
    /// Fitted states, in state order.
    pub targets: Vec<String>,
    /// Ξ: one row per target, one column per `file.library` term (zeros included).
    pub coefficients: DMatrix<f64>,
    /// The chosen coefficients' scores, one per target.
    pub rows: Vec<RowFit>,
    /// Every sweep value (one entry without a sweep).
    pub sweep: Vec<SweepPoint>,
    pub samples: usize,
    /// Library terms that are identically zero on the data, left out of the regression (coefficient 0).
    pub dropped_terms: Vec<String>,
    /// Library terms left out because they use an unexcited variable (`options.excluded_vars`).
    pub excluded_terms: Vec<String>,
    /// Ξ of every sweep value (same layout as `coefficients`).
    pub sweep_coefficients: Vec<DMatrix<f64>>,
    /// The sweep value (index into `sweep`) each target's row is taken from.
    pub chosen: Vec<usize>,
    /// The vx and vy rows (indices into `targets`) when they were fitted jointly in the heading
    /// frame: they always take the same sweep value ([`SindyFit::choose`]).
    pub heading_pair: Option<[usize; 2]>,
    /// `provenance.heading_frame` when the pair was fitted in the heading frame.
    heading_note: Option<Value>,
    options: SindyOptions,
    user_provenance: Value,
}

impl SindyFit {
    /// Take each target's row from sweep value `chosen[t]`: rebuilds `coefficients`, `rows` and `file`.
    /// The heading-frame pair ([`SindyFit::heading_pair`]) moves together: both rows take the
    /// sparser (larger) of their two sweep values.
    pub fn choose(&mut self, chosen: &[usize]) {
        assert_eq!(chosen.len(), self.targets.len(), "one sweep index per target");
        let mut chosen = chosen.to_vec();
        if let Some([a, b]) = self.heading_pair {
            let j = if self.sweep[chosen[b]].value > self.sweep[chosen[a]].value {
                chosen[b]
            } else {
                chosen[a]
            };
            chosen[a] = j;
            chosen[b] = j;
        }
        let (nt, nl) = (self.targets.len(), self.file.library.len());
        let mut coefficients = DMatrix::zeros(nt, nl);
        let mut rows = Vec::with_capacity(nt);
        for (t, &j) in chosen.iter().enumerate() {
            coefficients.set_row(t, &self.sweep_coefficients[j].row(t));
            rows.push(self.sweep[j].rows[t].clone());
        }
        let mut entries = Vec::new();
        for (t, state) in self.targets.iter().enumerate() {
            for (col, term) in self.file.library.iter().enumerate() {
                let c = coefficients[(t, col)];
                if c != 0.0 {
                    entries.push(Coefficient {
                        state: state.clone(),
                        term: term.clone(),
                        coefficient: c,
                    });
                }
            }
        }
        self.file.provenance = build_provenance(
            self.user_provenance.clone(),
            &self.options,
            self.samples,
            &self.targets,
            &rows,
            &self.sweep,
            (&self.dropped_terms, &self.excluded_terms),
        );
        if let (Some(note), Value::Object(p)) = (&self.heading_note, &mut self.file.provenance) {
            p.insert("heading_frame".into(), note.clone());
        }
        self.file.coefficients = entries;
        self.coefficients = coefficients;
        self.rows = rows;
        self.chosen = chosen;
    }

    /// The model file as pretty-printed JSON with a trailing newline.
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(&self.file).expect("a SindyFile serialises");
        s.push('\n');
        s
    }
}

fn names(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

/// Fit a SINDy model to `dataset`. `provenance` (an object, or anything else which is then kept
/// under `"source"`) is extended with the method, library, optimiser settings, selection and metrics.
pub fn fit(dataset: &Dataset, options: &SindyOptions, name: &str, provenance: Value) -> Result<SindyFit, SindyError> {
    fit_with_progress(dataset, options, name, provenance, &mut |_, _| {})
}

/// [`fit`], calling `progress(done, total)` after each sweep value's regression.
pub fn fit_with_progress(
    dataset: &Dataset,
    options: &SindyOptions,
    name: &str,
    provenance: Value,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<SindyFit, SindyError> {
    fit_in_chunks(dataset, options, name, provenance, progress, CHUNK_ROWS)
}

/// [`fit_with_progress`], the library's rows gathered `chunk` samples at a time
/// ([`accumulate`]: the chunk changes nothing but round-off).
fn fit_in_chunks(
    dataset: &Dataset,
    options: &SindyOptions,
    name: &str,
    provenance: Value,
    progress: &mut dyn FnMut(usize, usize),
    chunk: usize,
) -> Result<SindyFit, SindyError> {
    if name.trim().is_empty() {
        return Err(SindyError::EmptyName);
    }
    options.optimizer.validate()?;
    let vars: Vec<String> = DEFAULT_STATES
        .iter()
        .chain(DEFAULT_INPUTS.iter())
        .map(|s| s.to_string())
        .collect();
    let library = Library::new(options.library.terms(), &vars).expect("built-in libraries parse");
    let n = dataset.len();
    if n == 0 {
        return Err(SindyError::Empty);
    }
    let targets: Vec<String> = match options.rows {
        FittedRows::Dynamic => names(&DYNAMIC_STATES),
        FittedRows::All => names(&DEFAULT_STATES),
    };
    let target_idx: Vec<usize> = targets
        .iter()
        .map(|t| DEFAULT_STATES.iter().position(|s| s == t).expect("a default state"))
        .collect();
    // The data are checked first (the first sample with a non-finite state, input or target,
    // then the first non-finite interval end), then gathered in one pass (docs/sindy.md,
    // "Memory"): the library's rows are never held together.
    let interval = dataset.is_interval_form();
    for (k, (x, u, dx)) in dataset.samples().enumerate() {
        if x.iter().chain(u.iter()).chain(dx.iter()).any(|a| !a.is_finite()) {
            return Err(SindyError::NonFinite(k));
        }
    }
    if interval {
        if let Some(k) = dataset.interval_ends().position(|e| e.iter().any(|a| !a.is_finite())) {
            return Err(SindyError::NonFinite(k));
        }
    }
    // Terms of a variable the logs did not excite are left out (docs/sindy.md, "Unexcited
    // directions").
    let excluded: Vec<bool> = library
        .terms
        .iter()
        .map(|t| {
            t.factors.iter().any(|(b, _)| match b {
                Base::Var(v) | Base::Sin(v) | Base::Cos(v) => options.excluded_vars.contains(v),
            })
        })
        .collect();
    let excluded_terms: Vec<String> = (0..library.len())
        .filter(|&j| excluded[j])
        .map(|j| library.names[j].clone())
        .collect();
    let candidates: Vec<usize> = (0..library.len()).filter(|&j| !excluded[j]).collect();
    // The heading-frame pair (module heading_frame): vx and vy fitted jointly, the other rows as
    // before.
    let pair = options
        .heading_frame_active()
        .then(|| heading_frame::PairDesign::new(&options.excluded_vars, &vars));
    let pair_rows: Option<[usize; 2]> = pair.as_ref().map(|_| {
        let at = |s: &str| {
            targets
                .iter()
                .position(|t| t == s)
                .expect("dynamic rows hold vx and vy")
        };
        [at("vx"), at("vy")]
    });
    let main_t: Vec<usize> = (0..targets.len())
        .filter(|t| pair_rows.map_or(true, |p| !p.contains(t)))
        .collect();
    let main_targets: Vec<String> = main_t.iter().map(|&t| targets[t].clone()).collect();
    let rows = Rows {
        library: &library,
        columns: &candidates,
        targets: main_t.iter().map(|&t| target_idx[t]).collect(),
        pair: pair
            .as_ref()
            .zip(pair_rows)
            .map(|(d, [px, py])| (d, [target_idx[px], target_idx[py]])),
    };
    let (main_data, pair_data) = rows.gather(dataset, chunk);
    // Identically zero columns cannot be normalised and carry no information: leave them out.
    let kept_at: Vec<usize> = (0..candidates.len()).filter(|&c| main_data.nonzero[c]).collect();
    let kept: Vec<usize> = kept_at.iter().map(|&c| candidates[c]).collect();
    let dropped_terms: Vec<String> = (0..candidates.len())
        .filter(|&c| !main_data.nonzero[c])
        .map(|c| library.names[candidates[c]].clone())
        .collect();
    if n < kept.len() {
        return Err(SindyError::TooFewSamples {
            samples: n,
            terms: kept.len(),
        });
    }
    let with_targets =
        |at: &[usize], p: usize, t: usize| -> Vec<usize> { at.iter().copied().chain(p..p + t).collect() };
    let main_data = main_data.select(&with_targets(&kept_at, candidates.len(), main_t.len()));
    let y_stats: Vec<TargetStats> = main_t
        .iter()
        .map(|&t| TargetStats::of(dataset, target_idx[t], false))
        .collect();
    // The world library: the library's terms, then the pair's world terms it does not hold.
    let mut lib_names = library.names.clone();
    let mut world_col = Vec::new();
    let mut pair_fit = None;
    if let (Some(d), Some([px, py]), Some([top, bottom])) = (&pair, pair_rows, pair_data) {
        for t in &d.world_terms {
            let col = match library.terms.iter().position(|l| l == t) {
                Some(c) => c,
                None => match lib_names[library.len()..].iter().position(|nm| *nm == t.display(&vars)) {
                    Some(c) => library.len() + c,
                    None => {
                        lib_names.push(t.display(&vars));
                        lib_names.len() - 1
                    }
                },
            };
            world_col.push(col);
        }
        let pkept: Vec<usize> = (0..d.columns())
            .filter(|&j| top.nonzero[j] || bottom.nonzero[j])
            .collect();
        if 2 * n < pkept.len() {
            return Err(SindyError::TooFewSamples {
                samples: n,
                terms: pkept.len() / 2,
            });
        }
        let sel = with_targets(&pkept, d.columns(), 1);
        let parts = [top.select(&sel), bottom.select(&sel)];
        let joint = parts[0].stack(&parts[1]);
        let stats = [
            TargetStats::of(dataset, target_idx[px], true),
            TargetStats::of(dataset, target_idx[py], true),
        ];
        pair_fit = Some((joint, parts, stats, pkept));
    }

    let values_to_try: Vec<f64> = match &options.sweep {
        None => vec![options.optimizer.sparsity()],
        Some(v) if v.is_empty() => return Err(SindyError::EmptySweep),
        Some(v) => {
            if let Some(&bad) = v.iter().find(|a| !(a.is_finite() && **a >= 0.0)) {
                return Err(SindyError::BadSweepValue(bad));
            }
            v.clone()
        }
    };
    // The normalised library, the initial guess and the normal equations are the same for every
    // sweep value: computed once (optimizer::Prepared; the same numbers as regress per value).
    let mut prepared = optimizer::Prepared::from_data(&main_data, kept.len(), options.normalize_columns)?;
    let mut prepared_pair = match &pair_fit {
        Some((joint, _, _, pkept)) => Some(optimizer::Prepared::from_data(
            joint,
            pkept.len(),
            options.normalize_columns,
        )?),
        None => None,
    };
    let mut regressions = Vec::with_capacity(values_to_try.len());
    let mut pair_regressions = Vec::with_capacity(values_to_try.len());
    for &value in &values_to_try {
        let opt = options.optimizer.with_sparsity(value);
        regressions.push(prepared.regress(&opt)?);
        if let Some(pp) = prepared_pair.as_mut() {
            pair_regressions.push(pp.regress(&opt)?);
        }
        progress(regressions.len(), values_to_try.len());
    }
    drop(prepared_pair);
    // N of the criteria, per row, from the densest fit (most non-zero coefficients).
    let densest_of = |regs: &[optimizer::Regression]| {
        (0..regs.len())
            .max_by_key(|&j| (regs[j].coef.iter().filter(|&&c| c != 0.0).count(), usize::MAX - j))
            .unwrap_or(0)
    };
    let (n_ic_main, n_ic_pair): (Vec<f64>, [f64; 2]) = match options.sample_count {
        SampleCount::Raw => (vec![n as f64; main_t.len()], [n as f64; 2]),
        SampleCount::Effective => {
            let main_coef = &regressions[densest_of(&regressions)].coef;
            let pair_coef = pair_fit
                .as_ref()
                .map(|(_, _, _, pkept)| (&pair_regressions[densest_of(&pair_regressions)].coef, pkept.as_slice()));
            rows.effective_samples(dataset, (main_coef, &kept_at), pair_coef)
        }
    };
    let mut sweep = Vec::with_capacity(values_to_try.len());
    let mut sweep_coefficients = Vec::with_capacity(values_to_try.len());
    let mut pair_regs = pair_regressions.into_iter();
    for (&value, reg) in values_to_try.iter().zip(regressions) {
        let main_rows = score(&main_data, &y_stats, &reg.coef, &main_targets, value, &n_ic_main);
        let mut full = DMatrix::zeros(targets.len(), lib_names.len());
        for (k, &col) in kept.iter().enumerate() {
            for (i, &t) in main_t.iter().enumerate() {
                full[(t, col)] = reg.coef[(i, k)];
            }
        }
        let mut rows: Vec<Option<RowFit>> = vec![None; targets.len()];
        for (i, r) in main_t.iter().zip(main_rows) {
            rows[*i] = Some(r);
        }
        let (mut iterations, mut converged) = (reg.iterations, reg.converged);
        if let (Some(d), Some((_, parts, stats, pkept)), Some(pr), Some(pt)) =
            (&pair, &pair_fit, pair_regs.next(), pair_rows)
        {
            iterations = iterations.max(pr.iterations);
            converged &= pr.converged;
            let mut xi = vec![0.0; d.columns()];
            for (k, &j) in pkept.iter().enumerate() {
                xi[j] = pr.coef[(0, k)];
            }
            let world = d.world_rows(&xi);
            for (r, &t) in pt.iter().enumerate() {
                for (i, &c) in world[r].iter().enumerate() {
                    full[(t, world_col[i])] += c;
                }
            }
            let k_joint = pr.coef.iter().filter(|&&c| c != 0.0).count();
            let joint: Vec<f64> = pr.coef.row(0).iter().copied().collect();
            for (r, &t) in pt.iter().enumerate() {
                let rss = parts[r].rss(0, &joint);
                let TargetStats { tss, mean_square, .. } = stats[r];
                let base = aic(rss, n, n_ic_pair[r], 0, mean_square);
                rows[t] = Some(RowFit {
                    state: targets[t].clone(),
                    terms: full.row(t).iter().filter(|&&c| c != 0.0).count(),
                    rss,
                    rmse: (rss / n as f64).sqrt(),
                    r2: if tss > 0.0 { 1.0 - rss / tss } else { f64::NAN },
                    // The pair's joint coefficients, half to each row.
                    aic: base + k_joint as f64,
                    bic: base + 0.5 * k_joint as f64 * n_ic_pair[r].ln(),
                    sparsity: value,
                    n_ic: n_ic_pair[r],
                });
            }
        }
        let rows: Vec<RowFit> = rows.into_iter().map(|r| r.expect("every row scored")).collect();
        let total_aic = rows.iter().map(|r| r.aic).sum();
        let total_bic = rows.iter().map(|r| r.bic).sum();
        sweep.push(SweepPoint {
            value,
            iterations,
            converged,
            rows,
            total_aic,
            total_bic,
        });
        sweep_coefficients.push(full);
    }
    let mut chosen = select(&sweep, options.selection, options.criterion, targets.len());
    if let Some([a, b]) = pair_rows {
        // The pair takes one sweep value: the least summed criterion (ties: fewer terms, earlier).
        let ic = |r: &RowFit| match options.criterion {
            Criterion::Aic => r.aic,
            Criterion::Bic => r.bic,
        };
        let key = |j: usize| {
            let p = &sweep[j];
            (ic(&p.rows[a]) + ic(&p.rows[b]), p.rows[a].terms + p.rows[b].terms)
        };
        let mut best = chosen[a];
        if options.selection == AicSelection::PerRow {
            best = 0;
            for j in 1..sweep.len() {
                let (x, y) = (key(j), key(best));
                if x.0 < y.0 || (x.0 == y.0 && x.1 < y.1) {
                    best = j;
                }
            }
        }
        chosen[a] = best;
        chosen[b] = best;
    }
    let heading_note = pair.as_ref().map(|d| {
        json!({
            "rows": ["vx", "vy"],
            "mode": options.heading_frame.name(),
            "why": match options.heading_frame {
                HeadingFrame::Always => "always (--heading-frame always)",
                _ => "the heading was not excited: its terms cannot be identified in the world frame",
            },
            "form": "vx' = cos(yaw) F - sin(yaw) L, vy' = sin(yaw) F + cos(yaw) L; F, L over the heading-frame library with vx, vy standing for the heading-frame velocities cos(yaw) vx + sin(yaw) vy, -sin(yaw) vx + cos(yaw) vy; fitted jointly, written back expanded in world terms",
            "heading_frame_library": d.library.names,
            "world_terms_added": lib_names[library.len()..],
        })
    });
    let mut fit = SindyFit {
        file: SindyFile {
            format: FORMAT.to_string(),
            kind: "sindy".to_string(),
            name: name.to_string(),
            states: None,
            inputs: None,
            provenance: Value::Null,
            library: lib_names,
            kinematic: match options.rows {
                FittedRows::Dynamic => KINEMATIC.iter().map(|(a, b)| (a.to_string(), b.to_string())).collect(),
                FittedRows::All => Vec::new(),
            },
            coefficients: Vec::new(),
        },
        targets,
        coefficients: DMatrix::zeros(0, 0),
        rows: Vec::new(),
        sweep,
        samples: n,
        dropped_terms,
        excluded_terms,
        sweep_coefficients,
        chosen: Vec::new(),
        heading_pair: pair_rows,
        heading_note,
        options: options.clone(),
        user_provenance: provenance,
    };
    fit.choose(&chosen);
    Ok(fit)
}

/// N_eff = N / τ per row, τ = 1 + 2 Σ_{k≥1} ρ_k the integrated autocorrelation time of the residual of
/// `coef` (ρ_k its lag-k autocorrelation, summed while positive, up to [`MAX_LAG`]).
/// N / τ of one residual series (see [`effective_samples`]).
pub fn effective_count(r: &[f64]) -> f64 {
    let n = r.len();
    if n == 0 {
        return 1.0;
    }
    let mean = r.iter().sum::<f64>() / n as f64;
    let var: f64 = r.iter().map(|a| (a - mean).powi(2)).sum();
    let mut tau = 1.0;
    if var > 0.0 {
        for lag in 1..MAX_LAG.min(n) {
            let rho = (lag..n).map(|k| (r[k] - mean) * (r[k - lag] - mean)).sum::<f64>() / var;
            if rho <= 0.0 {
                break;
            }
            tau += 2.0 * rho;
        }
    }
    (n as f64 / tau).max(1.0)
}

pub fn effective_samples(theta: &DMatrix<f64>, y: &DMatrix<f64>, coef: &DMatrix<f64>) -> Vec<f64> {
    let residual = y - theta * coef.transpose();
    (0..y.ncols())
        .map(|t| effective_count(&residual.column(t).iter().copied().collect::<Vec<_>>()))
        .collect()
}

/// The longest lag of the autocorrelation sum in [`effective_samples`].
pub const MAX_LAG: usize = 200;

/// A target's mean, total sum of squares about it, and mean square (one pass each, in sample
/// order).
#[derive(Clone, Copy, Debug)]
struct TargetStats {
    tss: f64,
    mean_square: f64,
}

impl TargetStats {
    /// Of the derivative `i` of `dataset`'s samples (`std_sum`: summed as `Iterator::sum`, else as
    /// nalgebra's `mean` folds).
    fn of(dataset: &Dataset, i: usize, std_sum: bool) -> Self {
        let y = || dataset.samples().map(move |(_, _, dx)| dx[i]);
        let n = dataset.len() as f64;
        let sum: f64 = if std_sum {
            y().sum()
        } else {
            y().fold(0.0, |a, b| a + b)
        };
        let mean = sum / n;
        let tss: f64 = y().map(|a| (a - mean).powi(2)).sum();
        let mean_square = y().map(|a| a * a).sum::<f64>() / n;
        Self { tss, mean_square }
    }
}

/// Per-row RSS, RMSE, R², AIC and BIC of `coef` (targets × features) on the gathered data `data`
/// ([Θ | Ẏ]; the residual sums of squares from its R factor); the criteria use the sample counts
/// `n_ic` (one per target; see [`SampleCount`]).
fn score(
    data: &LsData,
    stats: &[TargetStats],
    coef: &DMatrix<f64>,
    targets: &[String],
    value: f64,
    n_ic: &[f64],
) -> Vec<RowFit> {
    let n = data.n as f64;
    targets
        .iter()
        .enumerate()
        .map(|(t, state)| {
            let xi: Vec<f64> = coef.row(t).iter().copied().collect();
            let rss = data.rss(t, &xi);
            let TargetStats { tss, mean_square: ms } = stats[t];
            let k = coef.row(t).iter().filter(|&&c| c != 0.0).count();
            RowFit {
                state: state.clone(),
                terms: k,
                rss,
                rmse: (rss / n).sqrt(),
                r2: if tss > 0.0 { 1.0 - rss / tss } else { f64::NAN },
                aic: aic(rss, data.n, n_ic[t], k, ms),
                bic: aic(rss, data.n, n_ic[t], k, ms) + ((n_ic[t].ln() - 2.0) * k as f64),
                sparsity: value,
                n_ic: n_ic[t],
            }
        })
        .collect()
}

/// The rows of the regression, evaluated one sample at a time: the library columns `columns`
/// (on the integral form the mean of the interval's two ends) and the main `targets` (state
/// indices of the derivatives), and with the heading-frame pair its design rows and targets.
struct Rows<'a> {
    library: &'a Library,
    columns: &'a [usize],
    targets: Vec<usize>,
    pair: Option<(&'a heading_frame::PairDesign, [usize; 2])>,
}

impl Rows<'_> {
    /// Every sample's rows, in order: `f(main row, pair rows)` (the main row: columns then targets;
    /// each pair row: its design then its target).
    fn each(&self, dataset: &Dataset, mut f: impl FnMut(&[f64], Option<[&[f64]; 2]>)) {
        let p = self.columns.len();
        let mut row = vec![0.0; p + self.targets.len()];
        let pc = self.pair.map_or(0, |(d, _)| d.columns());
        let mut prow = [vec![0.0; pc + 1], vec![0.0; pc + 1]];
        let mut ends = dataset.interval_ends();
        let interval = dataset.is_interval_form();
        for (x, u, dx) in dataset.samples() {
            let mut v = [0.0; 16];
            v[..12].copy_from_slice(x);
            v[12..].copy_from_slice(u);
            let e = if interval {
                ends.next().map(|x1| {
                    let mut e = v;
                    e[..12].copy_from_slice(x1);
                    e
                })
            } else {
                None
            };
            for (c, &j) in self.columns.iter().enumerate() {
                let t = &self.library.terms[j];
                let a = eval_term(t, &v);
                // The same operations as (Θ(x_k) + Θ(x_{k+1})) · 0.5 on the whole matrices.
                row[c] = match &e {
                    Some(e) => (a + eval_term(t, e)) * 0.5,
                    None => a,
                };
            }
            for (c, &i) in self.targets.iter().enumerate() {
                row[p + c] = dx[i];
            }
            match self.pair {
                Some((d, idx)) => {
                    let (mut top, mut bottom) = d.rows(&v);
                    if let Some(e) = &e {
                        let (t1, b1) = d.rows(e);
                        for j in 0..pc {
                            top[j] = 0.5 * (top[j] + t1[j]);
                            bottom[j] = 0.5 * (bottom[j] + b1[j]);
                        }
                    }
                    for (r, part) in [top, bottom].into_iter().enumerate() {
                        prow[r][..pc].copy_from_slice(&part);
                        prow[r][pc] = dx[idx[r]];
                    }
                    f(&row, Some([&prow[0], &prow[1]]));
                }
                None => f(&row, None),
            }
        }
    }

    /// The main rows and the pair's two parts (vx's and vy's equations), gathered in chunks of
    /// `chunk` samples.
    fn gather(&self, dataset: &Dataset, chunk: usize) -> (LsData, Option<[LsData; 2]>) {
        let mut main = Accumulator::new(self.columns.len() + self.targets.len(), chunk);
        let pc = self.pair.map_or(0, |(d, _)| d.columns());
        let mut pair = self
            .pair
            .map(|_| [Accumulator::new(pc + 1, chunk), Accumulator::new(pc + 1, chunk)]);
        self.each(dataset, |row, prows| {
            main.push(row);
            if let (Some(acc), Some(prows)) = (pair.as_mut(), prows) {
                acc[0].push(prows[0]);
                acc[1].push(prows[1]);
            }
        });
        (main.finish(), pair.map(|[a, b]| [a.finish(), b.finish()]))
    }

    /// N_eff per main target of the residuals of `main` (coefficients over the columns at `at`
    /// of [`Rows::columns`]), and of the pair's two parts under `pair` (joint coefficients over
    /// its design columns at the given positions): one more pass, holding the residual series.
    fn effective_samples(
        &self,
        dataset: &Dataset,
        main: (&DMatrix<f64>, &[usize]),
        pair: Option<(&DMatrix<f64>, &[usize])>,
    ) -> (Vec<f64>, [f64; 2]) {
        let (coef, at) = main;
        let p = self.columns.len();
        let n = dataset.len();
        let mut res: Vec<Vec<f64>> = vec![Vec::with_capacity(n); self.targets.len()];
        let mut pres: [Vec<f64>; 2] = match pair {
            Some(_) => [Vec::with_capacity(n), Vec::with_capacity(n)],
            None => [Vec::new(), Vec::new()],
        };
        self.each(dataset, |row, prows| {
            for (t, r) in res.iter_mut().enumerate() {
                let fit: f64 = at.iter().enumerate().map(|(c, &j)| row[j] * coef[(t, c)]).sum();
                r.push(row[p + t] - fit);
            }
            if let (Some((pcoef, pat)), Some(prows)) = (pair, prows) {
                for (r, prow) in pres.iter_mut().zip(prows) {
                    let y = prow[prow.len() - 1];
                    let fit: f64 = pat.iter().enumerate().map(|(c, &j)| prow[j] * pcoef[(0, c)]).sum();
                    r.push(y - fit);
                }
            }
        });
        let main = res.iter().map(|r| effective_count(r)).collect();
        let pair = match pair {
            Some(_) => [effective_count(&pres[0]), effective_count(&pres[1])],
            None => [n as f64; 2],
        };
        (main, pair)
    }
}

/// AIC = N_ic ln(σ²) + 2k with σ² = max(RSS/N, 1e-24 · mean(ẋ²), f64::MIN_POSITIVE) over the `n`
/// samples and `n_ic` the sample count of the criterion ([`SampleCount`]): the floor makes exact
/// fits (RSS ≈ 0 up to rounding) tie, so the sparser one wins.
pub fn aic(rss: f64, n: usize, n_ic: f64, k: usize, mean_square: f64) -> f64 {
    let sigma2 = (rss / n as f64).max(1e-24 * mean_square).max(f64::MIN_POSITIVE);
    n_ic * sigma2.ln() + 2.0 * k as f64
}

/// Index into `sweep` chosen for each target: the minimum AIC, ties to fewer terms, then to the
/// earlier sweep value.
fn select(sweep: &[SweepPoint], selection: AicSelection, criterion: Criterion, targets: usize) -> Vec<usize> {
    let ic = |r: &RowFit| match criterion {
        Criterion::Aic => r.aic,
        Criterion::Bic => r.bic,
    };
    let total = |p: &SweepPoint| match criterion {
        Criterion::Aic => p.total_aic,
        Criterion::Bic => p.total_bic,
    };
    let better = |a: (f64, usize), b: (f64, usize)| a.0 < b.0 || (a.0 == b.0 && a.1 < b.1);
    match selection {
        AicSelection::PerRow => (0..targets)
            .map(|t| {
                let mut best = 0;
                for j in 1..sweep.len() {
                    let (a, b) = (&sweep[j].rows[t], &sweep[best].rows[t]);
                    if better((ic(a), a.terms), (ic(b), b.terms)) {
                        best = j;
                    }
                }
                best
            })
            .collect(),
        AicSelection::Total => {
            let k = |p: &SweepPoint| p.rows.iter().map(|r| r.terms).sum::<usize>();
            let mut best = 0;
            for j in 1..sweep.len() {
                if better((total(&sweep[j]), k(&sweep[j])), (total(&sweep[best]), k(&sweep[best]))) {
                    best = j;
                }
            }
            vec![best; targets]
        }
    }
}

fn round6(v: f64) -> Value {
    if !v.is_finite() {
        return Value::Null;
    }
    let s = format!("{v:.6e}");
    json!(s.parse::<f64>().unwrap_or(v))
}

fn build_provenance(
    user: Value,
    options: &SindyOptions,
    samples: usize,
    targets: &[String],
    rows: &[RowFit],
    sweep: &[SweepPoint],
    (dropped, excluded): (&[String], &[String]),
) -> Value {
    let mut p = match user {
        Value::Object(m) => m,
        Value::Null => Map::new(),
        other => {
            let mut m = Map::new();
            m.insert("source".into(), other);
            m
        }
    };
    let per_row = |f: &dyn Fn(&RowFit) -> Value| -> Value {
        Value::Object(rows.iter().map(|r| (r.state.clone(), f(r))).collect())
    };
    p.insert("method".into(), json!("sindy"));
    p.insert("tool".into(), json!(format!("uavgen {}", env!("CARGO_PKG_VERSION"))));
    p.insert("library".into(), json!(options.library.name()));
    p.insert(
        "fitted_rows".into(),
        json!({
            "targets": targets,
            "kinematic_exact": options.rows == FittedRows::Dynamic,
        }),
    );
    p.insert("optimizer".into(), options.optimizer.to_json());
    p.insert("normalize_columns".into(), json!(options.normalize_columns));
    if let Some(values) = &options.sweep {
        p.insert(
            "sweep".into(),
            json!({
                "parameter": options.optimizer.sparsity_name(),
                "values": values,
                "criterion": options.criterion.name(),
                "penalty_per_term": match options.criterion {
                    Criterion::Aic => "2".to_string(),
                    Criterion::Bic => "ln N".to_string(),
                },
                "sample_count": match options.sample_count {
                    SampleCount::Raw => json!("raw"),
                    SampleCount::Effective => json!({
                        "kind": "effective: N / tau, tau = 1 + 2 sum of the positive residual autocorrelations",
                        "n": per_row(&|r| round6(r.n_ic)),
                    }),
                },
                "selection": match options.selection {
                    AicSelection::PerRow => "per row: each row takes the value minimising N ln(RSS_i/N) + penalty k_i",
                    AicSelection::Total => "total: one value for all rows, minimising the sum over rows",
                },
                "total_aic": sweep.iter().map(|s| round6(s.total_aic)).collect::<Vec<_>>(),
                "total_bic": sweep.iter().map(|s| round6(s.total_bic)).collect::<Vec<_>>(),
                "selected": per_row(&|r| json!(r.sparsity)),
            }),
        );
    }
    if !dropped.is_empty() {
        p.insert("dropped_zero_columns".into(), json!(dropped));
    }
    if !excluded.is_empty() {
        p.insert("excluded_unexcited_terms".into(), json!(excluded));
    }
    p.insert(
        "fit".into(),
        json!({
            "samples": samples,
            "derivative_rmse": per_row(&|r| round6(r.rmse)),
            "r2": per_row(&|r| round6(r.r2)),
            "aic": per_row(&|r| round6(r.aic)),
            "bic": per_row(&|r| round6(r.bic)),
            "terms": per_row(&|r| json!(r.terms)),
        }),
    );
    Value::Object(p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::dataset::SegmentData;

    /// Two segments of a toy vehicle in the integral form (x_{k+1} from one Euler step of known
    /// sparse dynamics, plus noise), random states and inputs.
    fn interval_dataset(n: usize) -> Dataset {
        let mut seed = 0x2545f4914f6cdd1du64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        let dt = 0.02;
        let segments = (0..2)
            .map(|s| {
                let mut seg = SegmentData {
                    log: s,
                    dt,
                    ..Default::default()
                };
                for k in 0..n {
                    let x: [f64; 12] = core::array::from_fn(|i| [5.0, 5.0, 5.0, 0.5, 0.5, 3.0][i % 6] * next());
                    let u: [f64; 4] = core::array::from_fn(|_| next());
                    let mut f = [0.0; 12];
                    f[..6].copy_from_slice(&x[6..]);
                    f[6] = -0.4 * x[6] + 9.81 * x[4].sin() * x[5].cos();
                    f[7] = -0.4 * x[7] - 9.81 * x[3].sin() * x[5].cos();
                    f[8] = 2.0 * u[0] - 2.0 * x[8];
                    f[9] = 16.0 * (u[1] - x[3]) - 6.0 * x[9];
                    f[10] = 16.0 * (u[2] - x[4]) - 6.0 * x[10];
                    f[11] = 3.0 * (u[3] - x[11]);
                    let x1: [f64; 12] = core::array::from_fn(|i| x[i] + dt * (f[i] + 0.05 * next()));
                    seg.t.push(k as f64 * dt);
                    seg.x.push(x);
                    seg.u.push(u);
                    seg.dx.push(core::array::from_fn(|i| (x1[i] - x[i]) / dt));
                    seg.x_next.push(x1);
                }
                seg
            })
            .collect();
        Dataset { segments }
    }

    /// The fit gathered in chunks of 1, 7 and more samples than the data selects the same terms
    /// with the same coefficients and scores to round-off; with and without the heading-frame pair.
    #[test]
    fn the_fit_does_not_depend_on_the_chunk_size() {
        let data = interval_dataset(150);
        let n = data.len();
        for heading_frame in [HeadingFrame::Never, HeadingFrame::Always] {
            let options = SindyOptions {
                sweep: Some(vec![0.05, 0.5, 2.0, 8.0]),
                heading_frame,
                ..SindyOptions::default()
            };
            let fits: Vec<SindyFit> = [1, 7, n + 1]
                .iter()
                .map(|&c| fit_in_chunks(&data, &options, "m", Value::Null, &mut |_, _| {}, c).unwrap())
                .collect();
            let one_shot = &fits[2];
            assert_eq!(one_shot.heading_pair.is_some(), heading_frame == HeadingFrame::Always);
            for f in &fits[..2] {
                assert_eq!(f.chosen, one_shot.chosen);
                for (a, b) in f.sweep_coefficients.iter().zip(&one_shot.sweep_coefficients) {
                    let scale = b.amax().max(1.0);
                    for (x, y) in a.iter().zip(b.iter()) {
                        assert_eq!(*x == 0.0, *y == 0.0, "{x} {y}");
                        assert!((x - y).abs() <= 1e-9 * scale, "{x} {y}");
                    }
                }
                for (a, b) in f.sweep.iter().zip(&one_shot.sweep) {
                    for (r, s) in a.rows.iter().zip(&b.rows) {
                        assert!((r.rss - s.rss).abs() <= 1e-9 * s.rss, "{} {}", r.rss, s.rss);
                        assert!((r.n_ic - s.n_ic).abs() <= 1e-9 * s.n_ic, "{} {}", r.n_ic, s.n_ic);
                    }
                }
            }
            // The selected model is the toy's: u_vz and vz in the vz row.
            let vz = one_shot.targets.iter().position(|t| t == "vz").unwrap();
            let at = |name: &str| one_shot.file.library.iter().position(|t| t == name).unwrap();
            assert!((one_shot.coefficients[(vz, at("u_vz"))] - 2.0).abs() < 0.05);
            assert!((one_shot.coefficients[(vz, at("vz"))] + 2.0).abs() < 0.05);
        }
    }

    /// The residual sums of squares from the gathered R are the direct sums over the samples.
    #[test]
    fn residual_sums_from_r_are_the_direct_ones() {
        let data = interval_dataset(60);
        let fit = fit(&data, &SindyOptions::default(), "m", Value::Null).unwrap();
        let vars: Vec<String> = DEFAULT_STATES
            .iter()
            .chain(DEFAULT_INPUTS.iter())
            .map(|s| s.to_string())
            .collect();
        let library = Library::new(fit.file.library.clone(), &vars).unwrap();
        for (t, state) in fit.targets.iter().enumerate() {
            let i = DEFAULT_STATES.iter().position(|s| s == state).unwrap();
            let mut rss = 0.0;
            for seg in &data.segments {
                for k in 0..seg.x.len() {
                    let v: Vec<f64> = seg.x[k].iter().chain(&seg.u[k]).copied().collect();
                    let e: Vec<f64> = seg.x_next[k].iter().chain(&seg.u[k]).copied().collect();
                    let pred: f64 = (0..library.len())
                        .map(|c| {
                            fit.coefficients[(t, c)]
                                * (eval_term(&library.terms[c], &v) + eval_term(&library.terms[c], &e))
                                * 0.5
                        })
                        .sum();
                    rss += (seg.dx[k][i] - pred).powi(2);
                }
            }
            assert!(
                (fit.rows[t].rss - rss).abs() <= 1e-9 * rss,
                "{state}: {} {rss}",
                fit.rows[t].rss
            );
        }
    }
}
