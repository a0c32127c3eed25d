//! Reference windows: the states r(t), r(t + DT), …, r(t + N·DT) the MPC tracks over its horizon.
//!
//! State convention (the standard order of the flight-log format, `LOG_FORMAT.md`):
//! `x y z roll pitch yaw vx vy vz roll_rate pitch_rate yaw_rate`. The built-in [`Trajectory`]s write
//! the position into indices 0, 1, 2 and, if `NX ≥ 9`, the analytic inertial velocity into indices
//! 6, 7, 8; every other entry is 0 (level attitude, yaw 0, no rates). With the default weights only
//! x, y, z and yaw are tracked, so the velocities matter only if the weights on vx, vy, vz are non-zero.
//! A model with fewer than 3 states gets the first `NX` position components.

use crate::Real;
use heapless::Deque;

/// Why a reference window could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ReferenceError {
    /// The source has nothing to give (an empty [`SetpointBuffer`]).
    Empty,
    /// A time or a reference value was NaN or infinite (e.g. the spiral's e^{0.06 t} overflowing
    /// f32 after about 1480 s).
    NonFinite,
}

impl core::fmt::Display for ReferenceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            ReferenceError::Empty => "no setpoint",
            ReferenceError::NonFinite => "non-finite reference",
        })
    }
}

/// A source of reference windows.
pub trait ReferenceSource<R: Real, const NX: usize, const N1: usize> {
    /// Fill `out[k]` with the reference state at time `t0 + k·dt`, k = 0..N1−1. On an error `out`
    /// may be partly written; the [`Controller`](crate::Controller) then falls back to its previous
    /// window.
    fn window(&mut self, t0: R, dt: R, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError>;

    /// [`window`](Self::window) with the times in f64, which the [`Controller`](crate::Controller)
    /// calls (it keeps time in f64 whatever `R` is). The default converts them to `R`; a source
    /// that must stay exact at large times with `R = f32` (f32 resolves 128 s at t = 1.7·10⁹ s,
    /// Unix time) overrides it and computes in f64, as [`Trajectory`] does.
    fn window_at(&mut self, t0: f64, dt: f64, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError> {
        self.window(R::from_f64(t0), R::from_f64(dt), out)
    }
}

/// The time of sample k of a window: `t0 + k·dt` (no accumulated rounding).
#[inline]
fn sample_time<R: Real>(t0: R, dt: R, k: usize) -> R {
    t0 + R::from_u32(u32::try_from(k).unwrap_or(u32::MAX)) * dt
}

/// Fill a window from a function of time.
fn fill_window<R: Real, const NX: usize, const N1: usize>(
    t0: R,
    dt: R,
    out: &mut [[R; NX]; N1],
    mut f: impl FnMut(R) -> [R; NX],
) -> Result<(), ReferenceError> {
    for (k, row) in out.iter_mut().enumerate() {
        *row = f(sample_time(t0, dt, k));
        if !row.iter().all(|v| v.is_finite()) {
            return Err(ReferenceError::NonFinite);
        }
    }
    Ok(())
}

/// The paper's reference trajectories (t in s, positions in m):
///
/// | trajectory | x | y | z |
/// | --- | --- | --- | --- |
/// | `Sinusoidal` | 4 sin(0.32 t) + 3 | 4 sin(0.64 t) | 2 sin(0.64 t) + 6 |
/// | `Circular` | 5 cos t | 5 sin t | 6 |
/// | `Spiral` | e^{0.06 t} cos t | e^{0.06 t} sin t | 0.1 t + 5 |
///
/// As a [`ReferenceSource`] it fills states as described in the [module docs](self).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Trajectory {
    /// x = 4 sin(0.32 t) + 3, y = 4 sin(0.64 t), z = 2 sin(0.64 t) + 6.
    Sinusoidal,
    /// x = 5 cos t, y = 5 sin t, z = 6.
    Circular,
    /// x = e^{0.06 t} cos t, y = e^{0.06 t} sin t, z = 0.1 t + 5.
    Spiral,
}

impl Trajectory {
    /// All three, in the paper's order.
    pub const ALL: [Trajectory; 3] = [Trajectory::Sinusoidal, Trajectory::Circular, Trajectory::Spiral];

    /// Position [x, y, z] in m at time `t` s.
    pub fn position<R: Real>(self, t: R) -> [R; 3] {
        let c = R::from_f64;
        match self {
            Trajectory::Sinusoidal => [
                c(4.0) * (c(0.32) * t).sin() + c(3.0),
                c(4.0) * (c(0.64) * t).sin(),
                c(2.0) * (c(0.64) * t).sin() + c(6.0),
            ],
            Trajectory::Circular => [c(5.0) * t.cos(), c(5.0) * t.sin(), c(6.0)],
            Trajectory::Spiral => {
                let e = (c(0.06) * t).exp();
                [e * t.cos(), e * t.sin(), c(0.1) * t + c(5.0)]
            }
        }
    }

    /// Inertial velocity [vx, vy, vz] in m/s at time `t` s (the time derivative of
    /// [`position`](Self::position)).
    pub fn velocity<R: Real>(self, t: R) -> [R; 3] {
        let c = R::from_f64;
        match self {
            Trajectory::Sinusoidal => [
                c(4.0 * 0.32) * (c(0.32) * t).cos(),
                c(4.0 * 0.64) * (c(0.64) * t).cos(),
                c(2.0 * 0.64) * (c(0.64) * t).cos(),
            ],
            Trajectory::Circular => [-c(5.0) * t.sin(), c(5.0) * t.cos(), R::ZERO],
            Trajectory::Spiral => {
                let e = (c(0.06) * t).exp();
                let (s, co) = (t.sin(), t.cos());
                [e * (c(0.06) * co - s), e * (c(0.06) * s + co), c(0.1)]
            }
        }
    }

    /// The reference state at time `t`: position in indices 0..3, velocity in 6..9 if `NX ≥ 9`,
    /// 0 elsewhere.
    pub fn state<R: Real, const NX: usize>(self, t: R) -> [R; NX] {
        let mut x = [R::ZERO; NX];
        for (xi, p) in x.iter_mut().zip(self.position(t)) {
            *xi = p;
        }
        if NX >= 9 {
            for (xi, v) in x.iter_mut().skip(6).zip(self.velocity(t)) {
                *xi = v;
            }
        }
        x
    }
}

impl<R: Real, const NX: usize, const N1: usize> ReferenceSource<R, NX, N1> for Trajectory {
    fn window(&mut self, t0: R, dt: R, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError> {
        let trajectory = *self;
        fill_window(t0, dt, out, |t| trajectory.state(t))
    }

    /// Evaluated in f64 and then converted to `R`: exact at any time for f32 crates too.
    fn window_at(&mut self, t0: f64, dt: f64, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError> {
        let trajectory = *self;
        for (k, row) in out.iter_mut().enumerate() {
            let t = sample_time(t0, dt, k);
            let state: [f64; NX] = trajectory.state(t);
            for (r, v) in row.iter_mut().zip(state) {
                *r = R::from_f64(v);
            }
            if !row.iter().all(|v| v.is_finite()) {
                return Err(ReferenceError::NonFinite);
            }
        }
        Ok(())
    }
}

/// The same state at every time (e.g. hover at a point).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConstantReference<R, const NX: usize>(pub [R; NX]);

impl<R: Real, const NX: usize, const N1: usize> ReferenceSource<R, NX, N1> for ConstantReference<R, NX> {
    fn window(&mut self, _t0: R, _dt: R, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError> {
        if !self.0.iter().all(|v| v.is_finite()) {
            return Err(ReferenceError::NonFinite);
        }
        *out = [self.0; N1];
        Ok(())
    }
}

/// A reference given by a function of time, `FnReference(|t| state)`.
#[derive(Clone, Copy, Debug)]
pub struct FnReference<F>(pub F);

impl<R: Real, F: FnMut(R) -> [R; NX], const NX: usize, const N1: usize> ReferenceSource<R, NX, N1> for FnReference<F> {
    fn window(&mut self, t0: R, dt: R, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError> {
        fill_window(t0, dt, out, &mut self.0)
    }
}

/// Why a [`SetpointBuffer`] operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SetpointError {
    /// The buffer holds `CAP` setpoints already (drop old ones with
    /// [`pop_expired`](SetpointBuffer::pop_expired)).
    Full,
    /// The time is not later than the last setpoint's.
    NotIncreasing,
    /// The time or a state value is NaN or infinite.
    NonFinite,
    /// The buffer is empty.
    Empty,
}

impl core::fmt::Display for SetpointError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            SetpointError::Full => "setpoint buffer full",
            SetpointError::NotIncreasing => "setpoint time not after the last one",
            SetpointError::NonFinite => "non-finite setpoint",
            SetpointError::Empty => "setpoint buffer empty",
        })
    }
}

/// How a [`SetpointBuffer`] fills times between setpoints.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Interpolation {
    /// The latest setpoint with time ≤ t.
    #[default]
    ZeroOrderHold,
    /// Linear between the setpoints before and after t.
    Linear,
}

/// Time-stamped setpoints `(t, state)` with strictly increasing times, at most `CAP` of them
/// (`CAP ≥ 1`, checked at compile time). Sampling at time t:
///
/// - before the first setpoint: the first setpoint;
/// - [`Interpolation::ZeroOrderHold`]: the latest setpoint with time ≤ t;
/// - [`Interpolation::Linear`]: linear between the latest setpoint with time ≤ t and the next one
///   (after the last setpoint: the last one);
/// - empty buffer: [`SetpointError::Empty`] ([`ReferenceError::Empty`] as a [`ReferenceSource`]).
///
/// Setpoints are never dropped implicitly: call [`pop_expired`](Self::pop_expired) with the current
/// time (e.g. [`Controller::time`](crate::Controller::time)) to free space.
#[derive(Clone, Debug)]
pub struct SetpointBuffer<R, const NX: usize, const CAP: usize> {
    points: Deque<(R, [R; NX]), CAP>,
    interpolation: Interpolation,
}

impl<R: Real, const NX: usize, const CAP: usize> Default for SetpointBuffer<R, NX, CAP> {
    fn default() -> Self {
        Self::new(Interpolation::ZeroOrderHold)
    }
}

impl<R: Real, const NX: usize, const CAP: usize> SetpointBuffer<R, NX, CAP> {
    /// An empty buffer.
    pub const fn new(interpolation: Interpolation) -> Self {
        Self {
            points: Deque::new(),
            interpolation,
        }
    }

    /// The interpolation in use.
    pub fn interpolation(&self) -> Interpolation {
        self.interpolation
    }

    /// Change the interpolation.
    pub fn set_interpolation(&mut self, interpolation: Interpolation) {
        self.interpolation = interpolation;
    }

    /// Number of setpoints held.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// No setpoints held.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// `len() == CAP`.
    pub fn is_full(&self) -> bool {
        self.points.is_full()
    }

    /// `CAP`.
    pub const fn capacity(&self) -> usize {
        CAP
    }

    /// Drop all setpoints.
    pub fn clear(&mut self) {
        self.points.clear();
    }

    /// Add a setpoint at time `t` (s). Errors: `NonFinite` if `t` or a state value is NaN or
    /// infinite, `NotIncreasing` if `t` ≤ the last setpoint's time, `Full` if `CAP` are held. On an
    /// error the buffer is unchanged.
    pub fn push(&mut self, t: R, state: [R; NX]) -> Result<(), SetpointError> {
        if !t.is_finite() || !state.iter().all(|v| v.is_finite()) {
            return Err(SetpointError::NonFinite);
        }
        if let Some((last, _)) = self.points.back() {
            if t <= *last {
                return Err(SetpointError::NotIncreasing);
            }
        }
        self.points.push_back((t, state)).map_err(|_| SetpointError::Full)
    }

    /// Drop the setpoints that no sample at a time ≥ `t` needs: all before the latest one with time
    /// ≤ `t` (that one is kept: it holds until the next). Returns how many were dropped.
    pub fn pop_expired(&mut self, t: R) -> usize {
        let mut dropped = 0;
        while self.points.len() >= 2 && self.get(1).is_some_and(|(t1, _)| *t1 <= t) {
            self.points.pop_front();
            dropped += 1;
        }
        dropped
    }

    /// The setpoints, oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &(R, [R; NX])> + '_ {
        self.points.iter()
    }

    /// The state at time `t` (see the type docs).
    pub fn sample(&self, t: R) -> Result<[R; NX], SetpointError> {
        let i = self.locate(t, 0)?;
        Ok(self.value_at(i, t))
    }

    /// Setpoint `i` (0 = oldest).
    fn get(&self, i: usize) -> Option<&(R, [R; NX])> {
        let (a, b) = self.points.as_slices();
        match i.checked_sub(a.len()) {
            None => a.get(i),
            Some(j) => b.get(j),
        }
    }

    /// Index of the latest setpoint with time ≤ `t` (0 if `t` is before the first), scanning from
    /// `hint` if that setpoint's time is ≤ `t` (so increasing times cost O(len) in total).
    fn locate(&self, t: R, hint: usize) -> Result<usize, SetpointError> {
        if self.points.is_empty() {
            return Err(SetpointError::Empty);
        }
        if !t.is_finite() {
            return Err(SetpointError::NonFinite);
        }
        let mut i = match self.get(hint) {
            Some((th, _)) if *th <= t => hint,
            _ => 0,
        };
        while let Some((tn, _)) = self.get(i.saturating_add(1)) {
            if *tn <= t {
                i = i.saturating_add(1);
            } else {
                break;
            }
        }
        Ok(i)
    }

    /// The value at `t` given `i = locate(t)`.
    fn value_at(&self, i: usize, t: R) -> [R; NX] {
        let Some((ta, a)) = self.get(i) else {
            return [R::ZERO; NX]; // unreachable: `i` comes from `locate`
        };
        if self.interpolation == Interpolation::ZeroOrderHold || t <= *ta {
            return *a;
        }
        let Some((tb, b)) = self.get(i.saturating_add(1)) else {
            return *a; // after the last setpoint
        };
        // ta < t < tb, so s ∈ [0, 1] (rounding is monotonic).
        let s = (t - *ta) / (*tb - *ta);
        let mut out = *a;
        for ((o, &va), &vb) in out.iter_mut().zip(a.iter()).zip(b.iter()) {
            let v = (R::ONE - s) * va + s * vb;
            // Finite endpoints can still overflow near the range limit: hold instead.
            *o = if v.is_finite() { v } else { va };
        }
        out
    }
}

impl<R: Real, const NX: usize, const N1: usize, const CAP: usize> ReferenceSource<R, NX, N1>
    for SetpointBuffer<R, NX, CAP>
{
    fn window(&mut self, t0: R, dt: R, out: &mut [[R; NX]; N1]) -> Result<(), ReferenceError> {
        let mut hint = 0;
        for (k, row) in out.iter_mut().enumerate() {
            let t = sample_time(t0, dt, k);
            hint = self.locate(t, hint).map_err(|e| match e {
                SetpointError::Empty => ReferenceError::Empty,
                _ => ReferenceError::NonFinite,
            })?;
            *row = self.value_at(hint, t);
        }
        Ok(())
    }
}
