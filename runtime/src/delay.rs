//! Input-delay compensation: predict the state over the known input delays, so that the MPC
//! solves from the state the aircraft will be in when its command takes effect.
//!
//! A command sent at sample k reaches channel i of the aircraft at sample k + dᵢ (dᵢ = the
//! generated crate's `INPUT_DELAY_SAMPLES[i]`). Over the samples k, k+1, …, k+D−1, with
//! D = minᵢ dᵢ the delay every channel shares, every channel is driven by inputs already sent:
//! the prediction
//!
//! ```text
//! x̂₀ = x_k (measured),   x̂ₘ₊₁ = F(x̂ₘ, ûₘ),   ûₘ,ᵢ = u_{k+m−dᵢ, i}   m = 0 … D−1
//! ```
//!
//! gives x̂_D, the state when the command computed now takes effect on the fastest channel. With
//! F the crate's `discrete_dynamics` this is exact (up to the model).
//!
//! **Channels with different delays.** The rest of channel i's delay, its lead dᵢ − D
//! (`INPUT_LEAD[i]` of a generated crate), is the solver's: its plan holds channel i's inputs at
//! stages k < `INPUT_LEAD[i]` (sent already, not decisions) and the input it returns for channel i
//! is the one planned at stage `INPUT_LEAD[i]` (docs/mpc.md, "Input delays"). Predicting over the
//! largest delay instead, with the not-yet-sent inputs held, tells the MPC that the faster
//! channels answer later than they do; its closed loop then chatters between the input bounds.
//!
//! Delays are whole samples: `INPUT_DELAY` rounded at generation; the rest (at most DT/2) is not
//! compensated.

use crate::disturbance::DisturbanceObserver;
use crate::Real;

/// Something that maps the measured state to the state the MPC should solve from, given the
/// inputs sent so far. [`Controller`](crate::Controller) calls it in `feedback` and tells it every
/// input it hands out when time advances.
pub trait StatePredictor<R, const NX: usize, const NU: usize> {
    /// The state to solve from, for the measured state `x`.
    fn predict(&self, x: &[R; NX]) -> [R; NX];
    /// The input that was applied over the sample that just ended (called once per sample).
    fn record(&mut self, u: &[R; NU]);
    /// Forget the history: as if `u` had been applied forever.
    fn reset(&mut self, u: &[R; NU]);
    /// How many samples ahead `predict` looks (D): the controller's reference window starts that
    /// many samples after the current time.
    fn lookahead(&self) -> usize {
        0
    }
    /// The measurement of the current sample, before `predict` (a disturbance observer's update;
    /// nothing by default).
    fn measure(&mut self, _x: &[R; NX]) {}
    /// The disturbance e of x⁺ = F(x, u) + e the solver should predict with, if the predictor
    /// estimates one (crate::disturbance; none by default).
    fn disturbance(&self) -> Option<&[R; NX]> {
        None
    }
}

/// No delay: the measured state, unchanged (the [`Controller`](crate::Controller)'s default).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NoDelay;

impl<R: Copy, const NX: usize, const NU: usize> StatePredictor<R, NX, NU> for NoDelay {
    #[inline]
    fn predict(&self, x: &[R; NX]) -> [R; NX] {
        *x
    }
    #[inline]
    fn record(&mut self, _u: &[R; NU]) {}
    #[inline]
    fn reset(&mut self, _u: &[R; NU]) {}
}

/// A delay longer than the compensator's capacity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DelayTooLong {
    /// The input channel.
    pub channel: usize,
    /// Its delay in samples.
    pub delay: usize,
    /// The capacity `D`.
    pub capacity: usize,
}

impl core::fmt::Display for DelayTooLong {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "input {} has a delay of {} samples, more than the capacity {}",
            self.channel, self.delay, self.capacity
        )
    }
}

/// The delay compensator of the module docs: the last `D` inputs sent (a fixed array, no
/// allocation) and the discrete dynamics `F` (a generated crate's `discrete_dynamics`); with
/// [`with_disturbance_observer`](Self::with_disturbance_observer) also the disturbance observer of
/// crate::disturbance, whose estimate e then enters its prediction (F(x, u) + e) and the solver's.
///
/// ```
/// use uavgen_runtime::{DelayCompensator, StatePredictor};
///
/// // x⁺ = x + u, both channels delayed by 2 samples.
/// let f = |x: &[f64; 1], u: &[f64; 1]| [x[0] + u[0]];
/// let mut c = DelayCompensator::<f64, _, 1, 1, 4>::new(f, [2], [0.0]).unwrap();
/// c.record(&[1.0]); // sent 2 samples ago: active now
/// c.record(&[3.0]); // sent 1 sample ago: active from the next sample
/// assert_eq!(c.predict(&[10.0]), [14.0]);
/// ```
#[derive(Clone)]
pub struct DelayCompensator<R, F, const NX: usize, const NU: usize, const D: usize> {
    dynamics: F,
    delays: [usize; NU],
    /// history[j]: the input sent j + 1 samples ago.
    history: [[R; NU]; D],
    observer: Option<DisturbanceObserver<R, NX>>,
}

/// The delays and the history (the dynamics are a function and are not shown).
impl<R: core::fmt::Debug, F, const NX: usize, const NU: usize, const D: usize> core::fmt::Debug
    for DelayCompensator<R, F, NX, NU, D>
{
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("DelayCompensator")
            .field("delays", &self.delays)
            .field("history", &self.history)
            .field("observer", &self.observer)
            .finish_non_exhaustive()
    }
}

impl<R, F, const NX: usize, const NU: usize, const D: usize> DelayCompensator<R, F, NX, NU, D>
where
    R: Real,
    F: Fn(&[R; NX], &[R; NU]) -> [R; NX],
{
    /// A compensator for the per-channel `delays` in samples (a generated crate's
    /// `INPUT_DELAY_SAMPLES`), with `initial` as every past input (e.g. the hover input). `D` is
    /// the capacity: an error names the first delay above it.
    pub fn new(dynamics: F, delays: [usize; NU], initial: [R; NU]) -> Result<Self, DelayTooLong> {
        for (channel, &delay) in delays.iter().enumerate() {
            if delay > D {
                return Err(DelayTooLong {
                    channel,
                    delay,
                    capacity: D,
                });
            }
        }
        Ok(Self {
            dynamics,
            delays,
            history: [initial; D],
            observer: None,
        })
    }

    /// The same compensator running a disturbance observer with `gain` and the per-sample `bound`
    /// (a generated crate's `DISTURBANCE_GAIN`, `DISTURBANCE_BOUND`; crate::disturbance). With a
    /// gain of 0 or no positive bound it estimates nothing and the solver is never told a
    /// disturbance.
    pub fn with_disturbance_observer(mut self, gain: R, bound: [R; NX]) -> Self {
        let observer = DisturbanceObserver::new(gain, bound);
        self.observer = observer.is_active().then_some(observer);
        self
    }

    /// The disturbance observer, if it runs one.
    pub fn observer(&self) -> Option<&DisturbanceObserver<R, NX>> {
        self.observer.as_ref()
    }

    /// F(x, u) + e (e = the observer's estimate, 0 without one).
    fn step(&self, x: &[R; NX], u: &[R; NU]) -> [R; NX] {
        let mut next = (self.dynamics)(x, u);
        if let Some(obs) = &self.observer {
            for (n, e) in next.iter_mut().zip(obs.estimate()) {
                *n += *e;
            }
        }
        next
    }

    /// The delays in samples.
    pub fn delays(&self) -> &[usize; NU] {
        &self.delays
    }

    /// The largest delay (the history `predict` reaches back over).
    pub fn max_delay(&self) -> usize {
        self.delays.iter().copied().max().unwrap_or(0)
    }

    /// The delay every channel shares (the smallest): the number of samples `predict` looks ahead.
    pub fn shared_delay(&self) -> usize {
        self.delays.iter().copied().min().unwrap_or(0)
    }

    /// The input sent `age` samples ago (1 = the latest), if the history reaches that far.
    pub fn sent(&self, age: usize) -> Option<&[R; NU]> {
        self.history.get(age.checked_sub(1)?)
    }

    /// The input active on each channel at sample k + m (k = now, m below the shared delay, so
    /// that every channel's was sent already).
    fn active(&self, m: usize) -> [R; NU] {
        let mut u = [R::ZERO; NU];
        for (i, (ui, &d)) in u.iter_mut().zip(&self.delays).enumerate() {
            // Sent at k + m − d, i.e. d − m ≥ 1 samples ago.
            if let Some(v) = self.sent(d.saturating_sub(m)).and_then(|s| s.get(i)) {
                *ui = *v;
            }
        }
        u
    }
}

impl<R, F, const NX: usize, const NU: usize, const D: usize> StatePredictor<R, NX, NU>
    for DelayCompensator<R, F, NX, NU, D>
where
    R: Real,
    F: Fn(&[R; NX], &[R; NU]) -> [R; NX],
{
    /// x̂_D from the measured x (module docs), with the observer's e added at every step. No
    /// shared delay: `x` itself.
    fn predict(&self, x: &[R; NX]) -> [R; NX] {
        let mut xm = *x;
        for m in 0..self.shared_delay() {
            xm = self.step(&xm, &self.active(m));
        }
        xm
    }

    fn record(&mut self, u: &[R; NU]) {
        self.history.rotate_right(1.min(D));
        if let Some(first) = self.history.first_mut() {
            *first = *u;
        }
        if let Some(obs) = self.observer.as_mut() {
            // Over the sample that just ended channel i was driven by the input sent dᵢ samples
            // before it: dᵢ + 1 samples ago now (the oldest kept if the history is shorter).
            let mut acted = [R::ZERO; NU];
            for (i, (a, &d)) in acted.iter_mut().zip(&self.delays).enumerate() {
                let sent = self.history.get(d).or(self.history.last());
                if let Some(v) = sent.and_then(|s| s.get(i)) {
                    *a = *v;
                }
            }
            obs.advance(&self.dynamics, &acted);
        }
    }

    fn reset(&mut self, u: &[R; NU]) {
        self.history = [*u; D];
        if let Some(obs) = self.observer.as_mut() {
            obs.reset();
        }
    }

    fn measure(&mut self, x: &[R; NX]) {
        if let Some(obs) = self.observer.as_mut() {
            obs.measure(x);
        }
    }

    fn disturbance(&self) -> Option<&[R; NX]> {
        self.observer.as_ref().map(DisturbanceObserver::estimate)
    }

    fn lookahead(&self) -> usize {
        self.shared_delay()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// x⁺ = x + u per channel (NX = NU = 2): a pure integrator, exact in floating point here.
    fn integrator(x: &[f64; 2], u: &[f64; 2]) -> [f64; 2] {
        [x[0] + u[0], x[1] + u[1]]
    }

    #[test]
    fn a_pure_integrator_delayed_by_two_samples_is_predicted_exactly() {
        let mut c = DelayCompensator::<f64, _, 2, 2, 3>::new(integrator, [2, 2], [0.0; 2]).unwrap();
        // Inputs sent at k−3, k−2, k−1 (k = now). With a delay of 2, samples k and k+1 are driven
        // by those sent at k−2 and k−1: x̂ = x + u_{k−2} + u_{k−1}.
        for u in [[100.0, 200.0], [1.0, -2.0], [0.5, 4.0]] {
            c.record(&u);
        }
        assert_eq!(c.predict(&[10.0, 20.0]), [11.5, 22.0]);
        assert_eq!(c.sent(1), Some(&[0.5, 4.0]));
        assert_eq!(c.sent(3), Some(&[100.0, 200.0]));
        assert_eq!(c.sent(4), None);
        assert_eq!(c.sent(0), None);
        // One sample later the input sent at k−2 has been applied and leaves the window.
        c.record(&[7.0, 7.0]);
        assert_eq!(c.predict(&[11.0, 18.0]), [11.0 + 0.5 + 7.0, 18.0 + 4.0 + 7.0]);
    }

    #[test]
    fn no_delay_is_the_identity() {
        let mut c = DelayCompensator::<f64, _, 2, 2, 4>::new(integrator, [0, 0], [0.0; 2]).unwrap();
        c.record(&[3.0, 3.0]);
        assert_eq!(c.predict(&[1.0, -1.0]), [1.0, -1.0]);
        assert_eq!(c.max_delay(), 0);
        // Zero capacity works too.
        let mut c0 = DelayCompensator::<f64, _, 2, 2, 0>::new(integrator, [0, 0], [0.0; 2]).unwrap();
        c0.record(&[3.0, 3.0]);
        assert_eq!(c0.predict(&[1.0, -1.0]), [1.0, -1.0]);
        assert_eq!(c0.sent(1), None);
        let n = NoDelay;
        assert_eq!(StatePredictor::<f64, 2, 2>::predict(&n, &[1.0, 2.0]), [1.0, 2.0]);
    }

    #[test]
    fn channels_with_different_delays_are_predicted_over_the_shared_delay() {
        // Channel 0 delayed by 3, channel 1 by 2: the shared delay is 2. Over k, k+1 channel 0
        // sees the inputs sent at k−3, k−2 and channel 1 those sent at k−2, k−1; the third sample
        // of channel 0's delay is the solver's (its lead).
        let mut c = DelayCompensator::<f64, _, 2, 2, 3>::new(integrator, [3, 2], [0.0; 2]).unwrap();
        for u in [[1.0, 10.0], [2.0, 20.0], [4.0, 40.0]] {
            c.record(&u);
        }
        assert_eq!((c.shared_delay(), c.max_delay()), (2, 3));
        assert_eq!(StatePredictor::<f64, 2, 2>::lookahead(&c), 2);
        assert_eq!(c.predict(&[0.0, 0.0]), [1.0 + 2.0, 20.0 + 40.0]);
        // One channel without delay: nothing is predicted.
        let c0 = DelayCompensator::<f64, _, 2, 2, 3>::new(integrator, [3, 0], [5.0; 2]).unwrap();
        assert_eq!(c0.predict(&[1.0, 1.0]), [1.0, 1.0]);
    }

    #[test]
    fn history_starts_at_the_initial_input_and_reset_refills_it() {
        let mut c = DelayCompensator::<f64, _, 2, 2, 2>::new(integrator, [2, 2], [1.0, 2.0]).unwrap();
        assert_eq!(c.predict(&[0.0, 0.0]), [2.0, 4.0]);
        c.record(&[5.0, 5.0]);
        c.reset(&[-1.0, 0.5]);
        assert_eq!(c.predict(&[0.0, 0.0]), [-2.0, 1.0]);
    }

    /// A 2-state/2-input solver that records the states it is given and returns [k, 2k] at its
    /// k-th feedback (k = 1, 2, …).
    struct Recorder {
        states: [[f64; 2]; 8],
        calls: usize,
    }

    impl crate::MpcSolver<f64, 2, 2, 3> for Recorder {
        const DT: f64 = 0.1;
        const U_MIN: [f64; 2] = [-100.0; 2];
        const U_MAX: [f64; 2] = [100.0; 2];
        fn initialize(&mut self, _x0: &[f64; 2], _u: &[f64; 2]) {}
        fn prepare(&mut self, _reference: &[[f64; 2]; 3]) -> crate::Status {
            crate::Status::Solved
        }
        fn feedback(&mut self, x0: &[f64; 2]) -> crate::Solution<f64, 2> {
            self.states[self.calls] = *x0;
            self.calls += 1;
            let k = self.calls as f64;
            crate::Solution {
                u0: [k, 2.0 * k],
                status: crate::Status::Solved,
                qp_iterations: 1,
                cost: 0.0,
            }
        }
        fn shift(&mut self) {}
    }

    #[test]
    fn the_controller_solves_from_the_predicted_state_and_records_what_it_sent() {
        let solver = Recorder {
            states: [[0.0; 2]; 8],
            calls: 0,
        };
        let compensator = DelayCompensator::<f64, _, 2, 2, 2>::new(integrator, [2, 2], [0.0; 2]).unwrap();
        let mut c =
            crate::Controller::new(solver, crate::ConstantReference([0.0; 2])).with_delay_compensation(compensator);
        c.start(0.0).unwrap();
        // The reference window starts where the solver's state is: two samples ahead.
        assert_eq!((c.time(), c.reference_time()), (0.0, 0.2));
        // k = 0: nothing sent yet (history = the initial zeros): x̂ = x.
        assert_eq!(c.feedback(&[5.0, 5.0]).unwrap().u0, [1.0, 2.0]);
        assert_eq!(c.predicted_state(), &[5.0, 5.0]);
        c.prepare_next().unwrap();
        // k = 1: x̂ = x + u_{−1} + u_0 = x + 0 + [1, 2].
        assert_eq!(c.feedback(&[10.0, 10.0]).unwrap().u0, [2.0, 4.0]);
        assert_eq!(c.predicted_state(), &[11.0, 12.0]);
        c.prepare_next().unwrap();
        // k = 2: x̂ = x + u_0 + u_1.
        c.feedback(&[0.0, 0.0]).unwrap();
        assert_eq!(c.solver().states[..3], [[5.0, 5.0], [11.0, 12.0], [3.0, 6.0]]);
        assert_eq!(c.delay_compensator().sent(1), Some(&[2.0, 4.0]));
        c.delay_compensator_mut().reset(&[0.0; 2]);
        c.prepare_next().unwrap();
        assert_eq!(c.delay_compensator().sent(1), Some(&[3.0, 6.0]));
        assert_eq!(c.delay_compensator().sent(2), Some(&[0.0, 0.0]));
    }

    #[test]
    fn delays_beyond_the_capacity_are_rejected() {
        let e = DelayCompensator::<f64, _, 2, 2, 2>::new(integrator, [1, 3], [0.0; 2]).unwrap_err();
        assert_eq!(
            e,
            DelayTooLong {
                channel: 1,
                delay: 3,
                capacity: 2
            }
        );
        extern crate std;
        use std::string::ToString;
        assert_eq!(
            e.to_string(),
            "input 1 has a delay of 3 samples, more than the capacity 2"
        );
    }
}
