//! The symbolic model IR: ẋ = f(x, u) as a DAG, with its Jacobians.

pub mod corrections;
pub mod pd;
mod sindy;

use crate::model::{Dynamics, Model};
use crate::symbolic::{jacobian, Graph, Id, Tape};

/// Input delays (s) in whole samples of `dt`: round(delay / dt), the generated crate's
/// `INPUT_DELAY_SAMPLES` (and the C header's, the runtime's compensator's, `track --generic`'s).
pub fn delay_samples(delays: &[f64], dt: f64) -> Vec<usize> {
    delays.iter().map(|d| (d / dt).round() as usize).collect()
}

/// Each input's lead over the delay every input shares: dᵢ − minⱼ dⱼ, the generated crate's
/// `INPUT_LEAD` (docs/mpc.md "Input delays").
pub fn input_lead(samples: &[usize]) -> Vec<usize> {
    let shared = samples.iter().copied().min().unwrap_or(0);
    samples.iter().map(|d| d - shared).collect()
}

/// A model lowered to the symbolic graph. Graph variables are the states
/// (0..NX) followed by the inputs (NX..NX+NU). For a model with `corrections`
/// the states include the extra states (see [`corrections`]).
pub struct ModelIr {
    pub graph: Graph,
    pub nx: usize,
    pub nu: usize,
    pub state_names: Vec<String>,
    pub input_names: Vec<String>,
    /// Pure delay of each input in s (the model's `corrections.latency`; not part of f).
    pub input_delays: Vec<f64>,
    /// ẋᵢ = f[i]
    pub f: Vec<Id>,
    /// ∂fᵢ/∂xⱼ
    pub fx: Vec<Vec<Id>>,
    /// ∂fᵢ/∂uⱼ
    pub fu: Vec<Vec<Id>>,
    f_tape: Tape,
    jac_tape: Tape,
}

impl ModelIr {
    pub fn new(model: &Model) -> Self {
        let mut graph = Graph::new();
        let vars: Vec<Id> = model.variables().iter().map(|n| graph.var(n)).collect();
        let (nx, nu) = (model.nx(), model.nu());
        // The base model sees its own states and the effective inputs (lag states for lagged inputs).
        let seen = corrections::effective_inputs(&mut graph, model, &vars);
        let base_vars: Vec<Id> = vars[..model.base_nx()].iter().copied().chain(seen).collect();
        let build = |graph: &mut Graph, vars: &[Id]| match &model.dynamics {
            Dynamics::Pd(p) => pd::dynamics(graph, vars, p),
            Dynamics::Sindy(s) => sindy::dynamics(graph, vars, s),
        };
        let mut base = build(&mut graph, &base_vars);
        if let Some(c) = &model.corrections {
            corrections::loop_mismatch(&mut graph, model, c, &base_vars, &mut base, build);
        }
        let f = match &model.corrections {
            Some(c) => corrections::apply(&mut graph, model, c, &vars, base),
            None => base,
        };
        let all: Vec<usize> = (0..nx + nu).collect();
        let jac = jacobian(&mut graph, &f, &all);
        let fx: Vec<Vec<Id>> = jac.iter().map(|r| r[..nx].to_vec()).collect();
        let fu: Vec<Vec<Id>> = jac.iter().map(|r| r[nx..].to_vec()).collect();
        let f_tape = Tape::new(&graph, &f);
        let flat: Vec<Id> = jac.iter().flatten().copied().collect();
        let jac_tape = Tape::new(&graph, &flat);
        Self {
            graph,
            nx,
            nu,
            state_names: model.states.clone(),
            input_names: model.inputs.clone(),
            input_delays: model.input_delays(),
            f,
            fx,
            fu,
            f_tape,
            jac_tape,
        }
    }

    /// Each input's lead over the delay every input shares, in samples of `dt` ([`input_lead`] of
    /// [`delay_samples`]).
    pub fn input_lead(&self, dt: f64) -> Vec<usize> {
        input_lead(&delay_samples(&self.input_delays, dt))
    }

    fn vars(&self, x: &[f64], u: &[f64]) -> Vec<f64> {
        assert_eq!(x.len(), self.nx, "state length");
        assert_eq!(u.len(), self.nu, "input length");
        x.iter().chain(u).copied().collect()
    }

    /// ẋ = f(x, u), evaluated by the interpreter.
    pub fn eval_f(&self, x: &[f64], u: &[f64]) -> Vec<f64> {
        self.f_tape.eval(&self.vars(x, u))
    }

    /// [`ModelIr::eval_f`] into `out` (NX values) without allocating; `vars` = x then u.
    pub fn eval_f_into(&self, vars: &[f64], out: &mut [f64]) {
        self.f_tape.eval_into(vars, out)
    }

    /// The tape of f (variables: x then u), for partial re-evaluation ([`crate::symbolic::Partial`]).
    pub fn f_tape(&self) -> &Tape {
        &self.f_tape
    }

    /// (∂f/∂x, ∂f/∂u) as row-major dense matrices (NX×NX, NX×NU).
    pub fn eval_jacobian(&self, x: &[f64], u: &[f64]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
        let flat = self.jac_tape.eval(&self.vars(x, u));
        let n = self.nx + self.nu;
        let fx = (0..self.nx).map(|i| flat[i * n..i * n + self.nx].to_vec()).collect();
        let fu = (0..self.nx)
            .map(|i| flat[i * n + self.nx..(i + 1) * n].to_vec())
            .collect();
        (fx, fu)
    }

    /// Number of structurally non-zero entries of [∂f/∂x ∂f/∂u].
    pub fn jacobian_nonzeros(&self) -> usize {
        self.fx
            .iter()
            .chain(&self.fu)
            .flatten()
            .filter(|&&id| !self.graph.is_zero(id))
            .count()
    }
}
