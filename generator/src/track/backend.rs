//! The MPC behind `uavgen track`: the generated crate through the runtime's `Controller` in a
//! harness process, or the generic reference solver in-process.

use crate::reference::{GenericMpc, MpcProblem};
use crate::{Model, ModelIr, MpcOptions};
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::time::Instant;
use uavgen_runtime::{disturbance, Trajectory};

/// One closed-loop sample's answer from the MPC.
#[derive(Clone, Debug, PartialEq)]
pub struct StepAnswer {
    pub u: Vec<f64>,
    /// The solver's status name (`Solved`, `IterationCap`, …).
    pub status: String,
    pub qp_iterations: usize,
    /// Time of the feedback phase (the measurement-to-input latency) and of the preparation of
    /// the next sample, in ns.
    pub feedback_ns: f64,
    pub prepare_ns: f64,
    /// `-` or what the runtime controller reported (`InvalidState`, `InputClamped`, …).
    pub error: String,
}

/// A real-time-iteration MPC that tracks one of the paper's trajectories.
pub trait Backend {
    /// Input bounds (u_min, u_max).
    fn bounds(&self) -> (Vec<f64>, Vec<f64>);
    /// Reset the guess to the constant (x0, u) and prepare the first QP at time t0.
    fn start(&mut self, trajectory: Trajectory, t0: f64, x0: &[f64], u: &[f64]) -> Result<(), String>;
    /// Feedback for the measured state x, then preparation of the next sample.
    fn step(&mut self, x: &[f64]) -> Result<StepAnswer, String>;
    /// What runs: "generated crate <name> via uavgen-runtime" or "generic solver".
    fn describe(&self) -> String;
}

/// The harness process (runtime/track-harness) driven over stdin/stdout.
pub struct HarnessBackend {
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
    nx: usize,
    nu: usize,
    u_min: Vec<f64>,
    u_max: Vec<f64>,
    name: String,
}

impl HarnessBackend {
    /// Start the harness binary and read its dimensions.
    pub fn spawn(binary: &std::path::Path, name: &str) -> Result<Self, String> {
        let mut child = Command::new(binary)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .map_err(|e| format!("{}: {e}", binary.display()))?;
        let stdin = child.stdin.take().ok_or("harness: no stdin")?;
        let stdout = BufReader::new(child.stdout.take().ok_or("harness: no stdout")?);
        let mut h = Self {
            child,
            stdin,
            stdout,
            nx: 0,
            nu: 0,
            u_min: Vec::new(),
            u_max: Vec::new(),
            name: name.to_string(),
        };
        let dims = h.request("dims")?;
        let w: Vec<&str> = dims.split_whitespace().collect();
        let parse = |s: &str| s.parse::<f64>().map_err(|_| format!("harness: bad dims '{dims}'"));
        if w.len() < 5 || w[0] != "dims" {
            return Err(format!("harness: bad dims '{dims}'"));
        }
        h.nx = parse(w[1])? as usize;
        h.nu = parse(w[2])? as usize;
        if w.len() != 5 + 2 * h.nu {
            return Err(format!("harness: bad dims '{dims}'"));
        }
        h.u_min = w[5..5 + h.nu].iter().map(|s| parse(s)).collect::<Result<_, _>>()?;
        h.u_max = w[5 + h.nu..].iter().map(|s| parse(s)).collect::<Result<_, _>>()?;
        Ok(h)
    }

    fn request(&mut self, line: &str) -> Result<String, String> {
        writeln!(self.stdin, "{line}")
            .and_then(|()| self.stdin.flush())
            .map_err(|e| format!("harness: {e}"))?;
        let mut answer = String::new();
        self.stdout
            .read_line(&mut answer)
            .map_err(|e| format!("harness: {e}"))?;
        if answer.is_empty() {
            return Err("harness: exited unexpectedly".into());
        }
        if let Some(e) = answer.strip_prefix("error ") {
            return Err(format!("harness: {}", e.trim()));
        }
        Ok(answer.trim().to_string())
    }

    pub fn nx(&self) -> usize {
        self.nx
    }
}

fn join(v: &[f64]) -> String {
    v.iter().map(|a| format!("{a:?}")).collect::<Vec<_>>().join(" ")
}

/// The harness's name for a trajectory.
pub fn trajectory_word(t: Trajectory) -> &'static str {
    match t {
        Trajectory::Sinusoidal => "sinusoid",
        Trajectory::Circular => "circle",
        Trajectory::Spiral => "spiral",
    }
}

impl Backend for HarnessBackend {
    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        (self.u_min.clone(), self.u_max.clone())
    }

    fn start(&mut self, trajectory: Trajectory, t0: f64, x0: &[f64], u: &[f64]) -> Result<(), String> {
        if x0.len() != self.nx || u.len() != self.nu {
            return Err(format!("harness: expects {} states and {} inputs", self.nx, self.nu));
        }
        let line = format!("start {} {t0:?} {} {}", trajectory_word(trajectory), join(x0), join(u));
        self.request(&line).map(|_| ())
    }

    fn step(&mut self, x: &[f64]) -> Result<StepAnswer, String> {
        let answer = self.request(&format!("step {}", join(x)))?;
        let w: Vec<&str> = answer.split_whitespace().collect();
        let bad = || format!("harness: unexpected answer '{answer}'");
        if w.len() != 1 + self.nu + 5 || w[0] != "u" {
            return Err(bad());
        }
        let num = |s: &str| s.parse::<f64>().map_err(|_| bad());
        Ok(StepAnswer {
            u: w[1..1 + self.nu].iter().map(|s| num(s)).collect::<Result<_, _>>()?,
            status: w[1 + self.nu].to_string(),
            qp_iterations: num(w[2 + self.nu])? as usize,
            feedback_ns: num(w[3 + self.nu])?,
            prepare_ns: num(w[4 + self.nu])?,
            error: w[5 + self.nu].to_string(),
        })
    }

    fn describe(&self) -> String {
        format!("generated crate `{}` through uavgen-runtime's Controller", self.name)
    }
}

impl Drop for HarnessBackend {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The generic reference solver (interpreted model, clarabel), one RTI step per sample.
///
/// A model with `corrections.latency` is compensated as the generated crate's harness does it
/// (uavgen-runtime's `DelayCompensator`, runtime/src/delay.rs): delays in whole samples
/// round(d/Δt), the MPC solves from the state predicted over the delay every channel shares
/// (D = the smallest) with the inputs already sent, and its reference window starts D samples
/// ahead; the solver holds each channel's inputs already sent beyond D (its lead) and sends the
/// one planned at the lead (docs/mpc.md "Input delays"). It runs the runtime's disturbance observer
/// too (uavgen-runtime's `DisturbanceObserver`, its estimate handed to the solver at the same points
/// of the timeline as the harness's `Controller` does: docs/mpc.md "Offset-free tracking").
pub struct GenericBackend {
    mpc: GenericMpc,
    options: MpcOptions,
    trajectory: Trajectory,
    t: f64,
    dt: f64,
    nx: usize,
    /// Input delay per channel in samples, and the inputs sent, the latest first (D of them).
    delays: Vec<usize>,
    history: Vec<Vec<f64>>,
    observer: Observer,
}

/// F(x, u) with the MPC's own model and substeps (the crate's `discrete_dynamics` in the harness).
fn model_step(mpc: &GenericMpc, x: &[f64], u: &[f64]) -> Vec<f64> {
    let p = mpc.problem();
    crate::discretize::discrete_step(mpc.ir(), x, u, p.dt, p.substeps)
}

/// uavgen-runtime's `DisturbanceObserver` (runtime/src/disturbance.rs) over a state of run-time
/// length: its update `disturbance::correct` at each fresh measurement, x̂ ← F(x̂, u) + e per sample.
struct Observer {
    gain: f64,
    bound: Vec<f64>,
    estimate: Vec<f64>,
    predicted: Vec<f64>,
    last: Option<Vec<f64>>,
    gap: u32,
}

impl Observer {
    fn active(&self) -> bool {
        self.gain > 0.0 && self.bound.iter().any(|b| *b > 0.0)
    }

    /// Forget the estimate and the last measurement (the runtime's `DisturbanceObserver::reset`).
    fn reset(&mut self) {
        self.estimate.iter_mut().for_each(|e| *e = 0.0);
        self.last = None;
        self.gap = 0;
    }

    fn measure(&mut self, x: &[f64]) {
        if !self.active() || !x.iter().all(|v| v.is_finite()) || self.last.as_deref() == Some(x) {
            return;
        }
        if self.last.is_some() {
            disturbance::correct(self.gain, &self.bound, &mut self.estimate, x, &self.predicted, self.gap);
        }
        self.last = Some(x.to_vec());
        self.predicted = x.to_vec();
        self.gap = 0;
    }

    fn advance(&mut self, next: impl Fn(&[f64]) -> Vec<f64>) {
        if self.last.is_none() || self.gap > disturbance::MAX_GAP {
            return;
        }
        let mut x = next(&self.predicted);
        for (xi, e) in x.iter_mut().zip(&self.estimate) {
            *xi += e;
        }
        self.predicted = x;
        self.gap += 1;
    }
}

impl GenericBackend {
    pub fn new(model: &Model, options: MpcOptions, horizon: usize, dt: f64, substeps: usize) -> Self {
        let problem = MpcProblem {
            horizon,
            dt,
            substeps,
            options: options.clone(),
        };
        let delays = crate::ir::delay_samples(&model.input_delays(), dt);
        let nx = model.nx();
        let bound = options.disturbance_bound(&model.states, dt);
        let observer = Observer {
            gain: options.disturbance_gain,
            bound,
            estimate: vec![0.0; nx],
            predicted: vec![0.0; nx],
            last: None,
            gap: 0,
        };
        Self {
            mpc: GenericMpc::new(ModelIr::new(model), problem),
            options,
            trajectory: Trajectory::Circular,
            t: 0.0,
            dt,
            nx: model.nx(),
            delays,
            history: Vec::new(),
            observer,
        }
    }

    /// D: the input delay every channel shares (the smallest), in samples.
    fn lookahead(&self) -> usize {
        self.delays.iter().copied().min().unwrap_or(0)
    }

    /// x̂_D: the state when the input computed now takes effect on the fastest channel,
    /// x̂ₘ₊₁ = F(x̂ₘ, ûₘ), ûₘ,ᵢ = u_{k+m−dᵢ, i} (all sent already: m < D ≤ dᵢ).
    fn predict(&self, x: &[f64]) -> Vec<f64> {
        let mut xm = x.to_vec();
        for m in 0..self.lookahead() {
            let u: Vec<f64> = self
                .delays
                .iter()
                .enumerate()
                .map(|(i, &d)| {
                    let age = d - m; // m < D ≤ d
                    self.history.get(age - 1).map_or(0.0, |h| h[i])
                })
                .collect();
            xm = model_step(&self.mpc, &xm, &u);
            for (x, e) in xm.iter_mut().zip(&self.observer.estimate) {
                *x += e;
            }
        }
        xm
    }

    fn window(&self) -> Vec<Vec<f64>> {
        let n = self.mpc.problem().horizon;
        let lead = self.lookahead() as f64 * self.dt;
        (0..=n)
            .map(|k| {
                let t = self.t + lead + k as f64 * self.dt;
                let mut r = vec![0.0; self.nx];
                for (i, p) in self.trajectory.position(t).into_iter().enumerate() {
                    r[i] = p;
                }
                if self.nx >= 9 {
                    for (i, v) in self.trajectory.velocity(t).into_iter().enumerate() {
                        r[6 + i] = v;
                    }
                }
                r
            })
            .collect()
    }
}

impl Backend for GenericBackend {
    fn bounds(&self) -> (Vec<f64>, Vec<f64>) {
        (self.options.u_min.clone(), self.options.u_max.clone())
    }

    fn start(&mut self, trajectory: Trajectory, t0: f64, x0: &[f64], u: &[f64]) -> Result<(), String> {
        self.trajectory = trajectory;
        self.t = t0;
        self.mpc.initialize(x0, u);
        // The inputs sent over the largest delay and one more (the prediction reaches back over the
        // delay; the observer needs the input that acted over the sample before).
        self.history = vec![u.to_vec(); self.delays.iter().copied().max().unwrap_or(0) + 1];
        self.observer.reset();
        self.mpc.set_disturbance(&self.observer.estimate);
        Ok(())
    }

    fn step(&mut self, x: &[f64]) -> Result<StepAnswer, String> {
        let reference = self.window();
        let start = Instant::now();
        self.observer.measure(x);
        let x = self.predict(x);
        let result = self.mpc.rti_step(&x, &reference);
        let elapsed = start.elapsed().as_nanos() as f64;
        let (u, status, qp_iterations) = match result {
            Ok(s) => (s.u0, "Solved".to_string(), s.qp_iterations),
            Err(e) => (self.mpc.input_to_send(), format!("Failed({e})").replace(' ', "_"), 0),
        };
        self.mpc.shift();
        self.t += self.dt;
        // The active-set polish lands on the bounds up to rounding (1e-15); like the runtime's
        // Controller, apply the input clamped into them and say so when that was more than rounding.
        let mut error = "-".to_string();
        let u: Vec<f64> = u
            .iter()
            .zip(self.options.u_min.iter().zip(&self.options.u_max))
            .map(|(&v, (&lo, &hi))| {
                if v < lo - 1e-9 || v > hi + 1e-9 {
                    error = "InputClamped".into();
                }
                v.clamp(lo, hi)
            })
            .collect();
        self.history.rotate_right(1);
        self.history[0] = u.clone();
        // Over the sample that ends now channel i was driven by the input sent dᵢ samples before it.
        let acted: Vec<f64> = self
            .delays
            .iter()
            .enumerate()
            .map(|(i, &d)| self.history[d][i])
            .collect();
        let mpc = &self.mpc;
        self.observer.advance(|x| model_step(mpc, x, &acted));
        if self.observer.active() {
            self.mpc.set_disturbance(&self.observer.estimate);
        }
        Ok(StepAnswer {
            u,
            status,
            qp_iterations,
            feedback_ns: elapsed,
            prepare_ns: 0.0,
            error,
        })
    }

    fn describe(&self) -> String {
        "generic reference solver (interpreted model + clarabel, one RTI step per sample)".into()
    }
}
