//! The `corrections` block in the symbolic graph (docs/model-format.md#corrections).
//!
//! Graph variables of a corrected model: the 12 standard states, the extra states
//! (`<input>_lagged` in input order, `<state>_dot_lagged` in state order, then `flight_time`),
//! then the inputs. The base model is built on the 12 states and the *effective* inputs (the lag
//! state s for a lagged input, the input itself otherwise); its rows are `base`. A row with an
//! acceleration lag is replaced by its lag state ℓ. With v = [vx vy vz], a = the (vx, vy, vz)
//! rows after that replacement and T = a + g e_z (the thrust acceleration):
//!
//! ```text
//! v̇ = a − D₁ v − D₂ √(‖v‖² + ε²) v + b + e_z (κ + c t_f + gain ρ²) T_z
//!     D₁, D₂ = diag(xy, xy, z) of the linear and quadratic drag, ε = 0.1 m/s,
//!     ρ² = r² / (z² + r²) with r = R/4, t_f = flight_time
//! ṡ = (u − s) / τ        for each lagged input
//! ℓ̇ = (base − ℓ) / τ     for each lagged acceleration (its row of the base model)
//! ṫ_f = 1
//! ```
//!
//! Every correction is evaluated with the base model's `a` at the same state and input, then
//! they are summed. Latency is not part of f.

use crate::model::corrections::{DOT_LAGGED_SUFFIX, LAGGABLE_STATES, LOOPS, QUADRATIC_DRAG_EPSILON, STANDARD_GRAVITY};
use crate::model::{Corrections, Dynamics, Model};
use crate::symbolic::{Graph, Id};

/// Indices of the standard states the corrections act on.
const Z: usize = 2;
const VX: usize = 6;

/// g of the thrust corrections: the PD model's gravity, 9.81 m/s² for the other kinds.
pub fn gravity(model: &Model) -> f64 {
    match &model.dynamics {
        Dynamics::Pd(p) => p.gravity,
        Dynamics::Sindy(_) => STANDARD_GRAVITY,
    }
}

/// The inputs the base model sees: for each input, the variable of its lag state if it is
/// lagged, the input itself otherwise; times its `input_gain` if it has one. `vars` are all graph variables (states then inputs).
pub fn effective_inputs(g: &mut Graph, model: &Model, vars: &[Id]) -> Vec<Id> {
    let (nxb, nx) = (model.base_nx(), model.nx());
    let mut next_lag = nxb;
    let mut out = Vec::with_capacity(model.inputs.len());
    for (i, name) in model.inputs.iter().enumerate() {
        let seen = match model.corrections.as_ref().and_then(|c| c.lag(name)) {
            Some(_) => {
                next_lag += 1;
                vars[next_lag - 1]
            }
            None => vars[nx + i],
        };
        // input_gain: the base model sees k times what reaches it.
        let k = model.corrections.as_ref().map_or(1.0, |c| c.gain(name));
        out.push(if k == 1.0 {
            seen
        } else {
            let k = g.constant(k);
            g.mul(k, seen)
        });
    }
    out
}

/// `loop_mismatch`: each named loop's row of the base model becomes
/// gain · own + coupling · (row − own), own = the row rebuilt with every variable outside the loop
/// (its own states and input, [`LOOPS`]) set to 0. `base_vars`: the 12 states, then the inputs the
/// base model sees; `build` builds the base model's rows on such variables.
pub fn loop_mismatch(
    g: &mut Graph,
    model: &Model,
    c: &Corrections,
    base_vars: &[Id],
    base: &mut [Id],
    build: impl Fn(&mut Graph, &[Id]) -> Vec<Id>,
) {
    for (state, own_states, own_input) in LOOPS {
        let Some(m) = c.loop_mismatch.get(state) else {
            continue;
        };
        let Some(row) = model.states.iter().position(|s| s == state) else {
            continue;
        };
        let zero = g.zero();
        let own_vars: Vec<Id> = base_vars
            .iter()
            .enumerate()
            .map(|(k, &v)| {
                let keep = if k < 12 {
                    own_states.contains(&model.states[k].as_str())
                } else {
                    k - 12 == own_input
                };
                if keep {
                    v
                } else {
                    zero
                }
            })
            .collect();
        let own = build(g, &own_vars)[row];
        let coupling = g.sub(base[row], own);
        let gain = g.constant(m.gain);
        let scaled_own = g.mul(gain, own);
        let cg = g.constant(m.coupling);
        let scaled_coupling = g.mul(cg, coupling);
        base[row] = g.add(scaled_own, scaled_coupling);
    }
}

/// ẋ of the corrected model from the base model's rows `base` (one per base state).
pub fn apply(g: &mut Graph, model: &Model, c: &Corrections, vars: &[Id], base: Vec<Id>) -> Vec<Id> {
    let (nxb, nx) = (model.base_nx(), model.nx());
    // The acceleration lag states ℓ replace their base rows: (row, ℓ, τ).
    let dot_lags: Vec<(usize, Id, f64)> = dot_lag_states(model)
        .into_iter()
        .map(|(i, tau)| (dot_lag_row(&model.states[i]), vars[i], tau))
        .collect();
    let targets = base.clone();
    let mut base = base;
    for &(row, l, _) in &dot_lags {
        base[row] = l;
    }
    let v = [vars[VX], vars[VX + 1], vars[VX + 2]];
    let a = [base[VX], base[VX + 1], base[VX + 2]];
    let grav = g.constant(gravity(model));
    // T = a + g e_z
    let thrust = [a[0], a[1], g.add(a[2], grav)];
    let mut delta: [Vec<Id>; 3] = Default::default();

    // −diag(xy, xy, z) v
    if let Some(d) = c.linear_drag {
        for (k, coef) in [d.xy, d.xy, d.z].into_iter().enumerate() {
            let m = g.constant(-coef);
            delta[k].push(g.mul(m, v[k]));
        }
    }
    // −diag(xy, xy, z) √(‖v‖² + ε²) v
    if let Some(d) = c.quadratic_drag {
        let squares: Vec<Id> = v.iter().map(|&vk| g.powi(vk, 2)).collect();
        let eps2 = g.constant(QUADRATIC_DRAG_EPSILON * QUADRATIC_DRAG_EPSILON);
        let sum = g.sum(squares.into_iter().chain([eps2]));
        let speed = g.sqrt(sum);
        for (k, coef) in [d.xy, d.xy, d.z].into_iter().enumerate() {
            let m = g.constant(-coef);
            let sv = g.mul(speed, v[k]);
            delta[k].push(g.mul(m, sv));
        }
    }
    // b
    if let Some(b) = c.force_bias {
        for k in 0..3 {
            delta[k].push(g.constant(b[k]));
        }
    }
    // e_z κ T_z
    if let Some(kappa) = c.thrust_gain {
        let kappa = g.constant(kappa);
        delta[2].push(g.mul(kappa, thrust[2]));
    }
    // e_z c · t_f · T_z (flight_time is the last state)
    if let Some(d) = c.thrust_decay {
        let rate = g.constant(d.per_second);
        let scale = g.mul(rate, vars[nx - 1]);
        delta[2].push(g.mul(scale, thrust[2]));
    }
    // e_z · gain · T_z · r² / (z² + r²), r = R/4
    if let Some(e) = c.ground_effect {
        let r = e.rotor_radius / 4.0;
        let r2 = g.constant(r * r);
        let z2 = g.powi(vars[Z], 2);
        let den = g.add(z2, r2);
        let rho2 = g.div(r2, den);
        let gain = g.constant(e.gain);
        let t = g.mul(gain, thrust[2]);
        delta[2].push(g.mul(t, rho2));
    }

    let mut f = base;
    for (k, terms) in delta.into_iter().enumerate() {
        f[VX + k] = g.sum(std::iter::once(f[VX + k]).chain(terms));
    }
    // ṡ = (u − s) / τ, in the order of the extra states.
    let mut lag_state = nxb;
    for (i, name) in model.inputs.iter().enumerate() {
        if let Some(tau) = c.lag(name) {
            let s = vars[lag_state];
            let du = g.sub(vars[nx + i], s);
            let inv_tau = g.constant(1.0 / tau);
            f.push(g.mul(inv_tau, du));
            lag_state += 1;
        }
    }
    // ℓ̇ = (base − ℓ) / τ, in the order of the extra states.
    for &(row, l, tau) in &dot_lags {
        let d = g.sub(targets[row], l);
        let inv_tau = g.constant(1.0 / tau);
        f.push(g.mul(inv_tau, d));
    }
    if c.thrust_decay.is_some() {
        f.push(g.one());
    }
    debug_assert_eq!(f.len(), nx, "one row per state");
    f
}

/// The acceleration lag states of `model`: (index in the full state, τ), in state order.
pub fn dot_lag_states(model: &Model) -> Vec<(usize, f64)> {
    let Some(c) = &model.corrections else {
        return Vec::new();
    };
    model
        .states
        .iter()
        .enumerate()
        .filter_map(|(i, name)| Some((i, c.acceleration_lag(name.strip_suffix(DOT_LAGGED_SUFFIX)?)?)))
        .collect()
}

/// The row (standard state index) that the acceleration lag state `name` replaces.
fn dot_lag_row(name: &str) -> usize {
    let state = name.strip_suffix(DOT_LAGGED_SUFFIX).unwrap_or(name);
    VX + LAGGABLE_STATES
        .iter()
        .position(|s| *s == state)
        .expect("an acceleration lag state of a validated block")
}

/// The rows b the acceleration lag states of `lags` follow, read off `f` = ẋ of the corrected
/// model at the full state z: b = ℓ + τ ℓ̇ (b does not depend on ℓ).
pub fn dot_lag_targets(lags: &[(usize, f64)], z: &[f64], f: &[f64]) -> Vec<f64> {
    lags.iter().map(|&(i, tau)| z[i] + tau * f[i]).collect()
}

/// A first-order lag ℓ̇ = (b − ℓ)/τ over h seconds while b goes linearly from b₀ to b₁ (exact for
/// that first-order hold): ℓ⁺ = b₁ − rτ + (ℓ − b₀ + rτ) e^{−h/τ}, r = (b₁ − b₀)/h. How a flight
/// computer (and `track`, `evaluate`, `diagnose`) estimates an acceleration lag state from the
/// measured states and the inputs sent: b₀, b₁ the base model's row at the start and the end of
/// the sample, with the input held over it.
pub fn lag_foh(ell: f64, b0: f64, b1: f64, h: f64, tau: f64) -> f64 {
    let rt = (b1 - b0) / h * tau;
    b1 - rt + (ell - b0 + rt) * (-h / tau).exp()
}

// The inputs a model with `latency` and `actuator_lag` sees over each sample of a zero-order-hold
// log: used by `diagnose` and `identify` alike.

/// The delayed input, interval averages (`uavgen::diagnose::catalogue::inputs`: d = (n + α)Δt, ū_m = (1 − α) u_{m−n} + α u_{m−n−1}, indices clamped at 0).
pub fn delayed(u: &[f64], dt: f64, delay: f64) -> Vec<f64> {
    if delay <= 0.0 {
        return u.to_vec();
    }
    let samples = delay / dt;
    let n = samples.floor() as usize;
    let alpha = samples - n as f64;
    let at = |m: usize, back: usize| u[m.saturating_sub(back)];
    (0..u.len())
        .map(|m| (1.0 - alpha) * at(m, n) + alpha * at(m, n + 1))
        .collect()
}

/// The lag state s_m at the sample instants for the zero-order-hold input v (s_0 = v_0).
pub fn lag_states(v: &[f64], dt: f64, tau: f64) -> Vec<f64> {
    let a = (-dt / tau).exp();
    let mut s = Vec::with_capacity(v.len());
    let mut cur = v.first().copied().unwrap_or(0.0);
    for &vm in v {
        s.push(cur);
        cur = a * cur + (1.0 - a) * vm;
    }
    s
}

/// What the model sees of one channel over each interval: delayed, then lagged (interval average).
pub fn channel_average(u: &[f64], dt: f64, delay: f64, lag: Option<f64>) -> Vec<f64> {
    let v = delayed(u, dt, delay);
    match lag {
        None => v,
        Some(tau) => {
            let s = lag_states(&v, dt, tau);
            // (τ/Δt)(1 − a) = −(τ/Δt) expm1(−Δt/τ), accurate for small Δt/τ.
            let k = -(tau / dt) * (-dt / tau).exp_m1();
            v.iter().zip(&s).map(|(vm, sm)| vm + (sm - vm) * k).collect()
        }
    }
}
