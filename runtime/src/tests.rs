//! Unit tests with a fake solver.

extern crate std;

use std::vec::Vec;

use crate::*;

const NX: usize = 12;
const NU: usize = 4;
const N1: usize = 31;
const DT: f64 = 0.1;
const U_MIN: [f64; NU] = [-5.0, -0.611, -0.611, -2.618];
const U_MAX: [f64; NU] = [5.0, 0.611, 0.611, 2.618];

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * (1.0 + b.abs())
}

fn assert_close(a: f64, b: f64, tol: f64) {
    assert!(close(a, b, tol), "{a} != {b} (tol {tol})");
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Event {
    Initialize,
    Prepare,
    Feedback,
    Shift,
}

/// A 12-state/4-input solver stub: records every call and the reference it was given, returns a
/// fixed input (or, for a non-finite x0, its "previous plan's" first input with `InvalidInput`).
struct FakeSolver {
    events: Vec<Event>,
    references: Vec<[[f64; NX]; N1]>,
    states: Vec<[f64; NX]>,
    u: [f64; NU],
    previous_u: [f64; NU],
    status: Status,
    prepare_status: Status,
}

impl FakeSolver {
    fn new(u: [f64; NU]) -> Self {
        Self {
            events: Vec::new(),
            references: Vec::new(),
            states: Vec::new(),
            u,
            previous_u: [0.0; NU],
            status: Status::Solved,
            prepare_status: Status::Solved,
        }
    }
}

impl MpcSolver<f64, NX, NU, N1> for FakeSolver {
    const DT: f64 = DT;
    const U_MIN: [f64; NU] = U_MIN;
    const U_MAX: [f64; NU] = U_MAX;

    fn initialize(&mut self, _x0: &[f64; NX], u: &[f64; NU]) {
        self.events.push(Event::Initialize);
        self.previous_u = *u;
    }
    fn prepare(&mut self, reference: &[[f64; NX]; N1]) -> Status {
        self.events.push(Event::Prepare);
        self.references.push(*reference);
        self.prepare_status
    }
    fn feedback(&mut self, x0: &[f64; NX]) -> Solution<f64, NU> {
        self.events.push(Event::Feedback);
        self.states.push(*x0);
        if !x0.iter().all(|v| v.is_finite()) {
            return Solution {
                u0: self.previous_u,
                status: Status::InvalidInput,
                qp_iterations: 0,
                cost: 0.0,
            };
        }
        self.previous_u = self.u;
        Solution {
            u0: self.u,
            status: self.status,
            qp_iterations: 3,
            cost: 1.5,
        }
    }
    fn shift(&mut self) {
        self.events.push(Event::Shift);
    }
}

/// A counter that advances by the next entry of `steps` (cyclically) at every read.
struct StepCounter {
    now: u32,
    steps: Vec<u32>,
    reads: usize,
}

impl CycleCounter for StepCounter {
    fn cycles(&mut self) -> u32 {
        let step = self.steps[self.reads % self.steps.len()];
        self.reads += 1;
        self.now = self.now.wrapping_add(step);
        self.now
    }
}

// ---------------------------------------------------------------- Real

#[test]
fn real_helpers() {
    assert_eq!(f64::NAN.clamp_to(-1.0, 1.0), -1.0);
    assert_eq!(3.0f64.clamp_to(-1.0, 1.0), 1.0);
    assert_eq!((-3.0f32).clamp_to(-1.0, 1.0), -1.0);
    assert_eq!(0.5f32.clamp_to(-1.0, 1.0), 0.5);
    assert!(!<f32 as Real>::is_finite(f32::INFINITY));
    assert!(<f64 as Real>::is_nan(f64::NAN));
    assert_close(<f64 as Real>::exp(1.0), core::f64::consts::E, 1e-15);
    assert_eq!(<f32 as Real>::from_u32(3), 3.0);
    assert_eq!(<f64 as Real>::zero(), 0.0);
    assert_eq!(<f32 as Real>::one(), 1.0);
}

// ---------------------------------------------------------------- trajectories

#[test]
fn sinusoidal_matches_formula() {
    let tr = Trajectory::Sinusoidal;
    assert_eq!(tr.position(0.0f64), [3.0, 0.0, 6.0]);
    let v0 = tr.velocity(0.0f64);
    for (a, b) in v0.iter().zip([1.28, 2.56, 1.28]) {
        assert_close(*a, b, 1e-15);
    }
    // 0.64 t = π: sin(0.32 t) = 1, sin(0.64 t) = 0.
    let t = core::f64::consts::PI / 0.64;
    let p = tr.position(t);
    assert_close(p[0], 7.0, 1e-14);
    assert!(p[1].abs() < 1e-14);
    assert_close(p[2], 6.0, 1e-14);
    let v = tr.velocity(t);
    assert!(v[0].abs() < 1e-14);
    assert_close(v[1], -2.56, 1e-14);
    assert_close(v[2], -1.28, 1e-14);
    // t = 10: x = 4 sin 3.2 + 3 = 2.76650..., y = 4 sin 6.4 = 0.46620..., z = 2 sin 6.4 + 6.
    let p = tr.position(10.0f64);
    assert_close(p[0], 4.0 * 3.2f64.sin() + 3.0, 1e-15);
    assert_close(p[0], 2.766_503_426_289_68, 1e-12);
    assert_close(p[1], 0.466_196_819_401_974_6, 1e-12);
    assert_close(p[2], 6.233_098_409_700_987, 1e-12);
}

#[test]
fn circular_matches_formula() {
    let tr = Trajectory::Circular;
    assert_eq!(tr.position(0.0f64), [5.0, 0.0, 6.0]);
    assert_eq!(tr.velocity(0.0f64), [-0.0, 5.0, 0.0]);
    let t = core::f64::consts::FRAC_PI_2;
    let p = tr.position(t);
    assert!(p[0].abs() < 1e-15);
    assert_close(p[1], 5.0, 1e-15);
    assert_eq!(p[2], 6.0);
    let v = tr.velocity(t);
    assert_close(v[0], -5.0, 1e-15);
    assert!(v[1].abs() < 1e-15);
    // t = 1: (5 cos 1, 5 sin 1) = (2.70151..., 4.20735...).
    let p = tr.position(1.0f64);
    assert_close(p[0], 2.701_511_529_340_7, 1e-12);
    assert_close(p[1], 4.207_354_924_039_5, 1e-12);
}

#[test]
fn spiral_matches_formula() {
    let tr = Trajectory::Spiral;
    assert_eq!(tr.position(0.0f64), [1.0, 0.0, 5.0]);
    let v = tr.velocity(0.0f64);
    assert_close(v[0], 0.06, 1e-15);
    assert_close(v[1], 1.0, 1e-15);
    assert_close(v[2], 0.1, 1e-15);
    // t = 2π: e^{0.12π} = 1.45789...
    let t = 2.0 * core::f64::consts::PI;
    let e = 1.457_891_360_950_680_3;
    let p = tr.position(t);
    assert_close(p[0], e, 1e-12);
    assert!(p[1].abs() < 1e-14);
    assert_close(p[2], 0.2 * core::f64::consts::PI + 5.0, 1e-15);
    let v = tr.velocity(t);
    assert_close(v[0], 0.06 * e, 1e-12);
    assert_close(v[1], e, 1e-12);
}

#[test]
fn velocities_are_derivatives_of_positions() {
    let h = 1e-5;
    for tr in Trajectory::ALL {
        for t in [0.0, 0.7, 3.3, 12.0, 40.0] {
            let (pp, pm, v) = (tr.position(t + h), tr.position(t - h), tr.velocity(t));
            for i in 0..3 {
                assert_close((pp[i] - pm[i]) / (2.0 * h), v[i], 1e-8);
            }
        }
    }
}

#[test]
fn state_layout() {
    let tr = Trajectory::Circular;
    let t = 0.4f64;
    let (p, v) = (tr.position(t), tr.velocity(t));
    let x: [f64; 12] = tr.state(t);
    assert_eq!(x[0..3], p);
    assert_eq!(x[3..6], [0.0; 3]);
    assert_eq!(x[6..9], v);
    assert_eq!(x[9..12], [0.0; 3]);
    let x9: [f64; 9] = tr.state(t);
    assert_eq!(x9[6..9], v);
    // Fewer than 9 states: positions only.
    let x8: [f64; 8] = tr.state(t);
    assert_eq!(x8[0..3], p);
    assert_eq!(x8[3..8], [0.0; 5]);
    let x2: [f64; 2] = tr.state(t);
    assert_eq!(x2, [p[0], p[1]]);
    let x0: [f64; 0] = tr.state(t);
    assert_eq!(x0, []);
}

#[test]
fn f32_trajectories_agree_with_f64() {
    for tr in Trajectory::ALL {
        for t in [0.0f32, 1.25, 9.5, 30.0] {
            let (a, b) = (tr.position(t), tr.position(t as f64));
            for i in 0..3 {
                assert_close(a[i] as f64, b[i], 1e-5);
            }
        }
    }
}

#[test]
fn trajectory_windows_are_spaced_by_dt() {
    let mut window = [[0.0f64; NX]; N1];
    for mut tr in Trajectory::ALL {
        ReferenceSource::<f64, NX, N1>::window(&mut tr, 2.5, DT, &mut window).unwrap();
        for (k, row) in window.iter().enumerate() {
            let expected: [f64; NX] = tr.state(2.5 + k as f64 * DT);
            assert_eq!(*row, expected, "{tr:?} row {k}");
        }
    }
    // Last row at t0 + N·DT.
    let mut c = Trajectory::Circular;
    ReferenceSource::<f64, NX, N1>::window(&mut c, 0.0, DT, &mut window).unwrap();
    assert_close(window[30][0], 5.0 * 3.0f64.cos(), 1e-14);
}

#[test]
fn spiral_overflowing_f32_is_an_error() {
    let mut window = [[0.0f32; NX]; 3];
    let mut tr = Trajectory::Spiral;
    assert_eq!(tr.window(10.0, 0.1, &mut window), Ok(()));
    assert_eq!(tr.window(2000.0, 0.1, &mut window), Err(ReferenceError::NonFinite));
}

#[test]
fn constant_and_fn_references() {
    let mut window = [[0.0f64; 3]; 4];
    let mut c = ConstantReference([1.0, 2.0, 3.0]);
    c.window(5.0, DT, &mut window).unwrap();
    assert_eq!(window, [[1.0, 2.0, 3.0]; 4]);
    let mut bad = ConstantReference([1.0, f64::NAN, 3.0]);
    assert_eq!(bad.window(0.0, DT, &mut window), Err(ReferenceError::NonFinite));

    let mut f = FnReference(|t: f64| [t, 2.0 * t, 0.0]);
    f.window(1.0, 0.5, &mut window).unwrap();
    assert_eq!(
        window,
        [[1.0, 2.0, 0.0], [1.5, 3.0, 0.0], [2.0, 4.0, 0.0], [2.5, 5.0, 0.0]]
    );
    let mut g = FnReference(|t: f64| [1.0 / (t - 1.5), 0.0, 0.0]);
    assert_eq!(g.window(1.0, 0.5, &mut window), Err(ReferenceError::NonFinite));
}

// ---------------------------------------------------------------- setpoint buffer

fn sp(v: f64) -> [f64; 2] {
    [v, -v]
}

#[test]
fn setpoint_push_errors() {
    let mut b: SetpointBuffer<f64, 2, 3> = SetpointBuffer::default();
    assert_eq!(b.sample(0.0), Err(SetpointError::Empty));
    assert_eq!(b.push(1.0, sp(1.0)), Ok(()));
    assert_eq!(b.push(1.0, sp(2.0)), Err(SetpointError::NotIncreasing));
    assert_eq!(b.push(0.5, sp(2.0)), Err(SetpointError::NotIncreasing));
    assert_eq!(b.push(f64::NAN, sp(2.0)), Err(SetpointError::NonFinite));
    assert_eq!(b.push(f64::INFINITY, sp(2.0)), Err(SetpointError::NonFinite));
    assert_eq!(b.push(2.0, [0.0, f64::NAN]), Err(SetpointError::NonFinite));
    assert_eq!(b.push(2.0, [f64::NEG_INFINITY, 0.0]), Err(SetpointError::NonFinite));
    assert_eq!(b.len(), 1);
    assert_eq!(b.push(2.0, sp(2.0)), Ok(()));
    assert_eq!(b.push(3.0, sp(3.0)), Ok(()));
    assert!(b.is_full());
    assert_eq!(b.push(4.0, sp(4.0)), Err(SetpointError::Full));
    assert_eq!(b.len(), 3);
    assert_eq!(b.capacity(), 3);
    assert_eq!(b.sample(f64::NAN), Err(SetpointError::NonFinite));
    b.clear();
    assert!(b.is_empty());
}

#[test]
fn setpoint_zero_order_hold() {
    let mut b: SetpointBuffer<f64, 2, 8> = SetpointBuffer::new(Interpolation::ZeroOrderHold);
    b.push(1.0, sp(10.0)).unwrap();
    b.push(2.0, sp(20.0)).unwrap();
    b.push(4.0, sp(40.0)).unwrap();
    assert_eq!(b.sample(-5.0), Ok(sp(10.0))); // before the first: the first
    assert_eq!(b.sample(1.0), Ok(sp(10.0)));
    assert_eq!(b.sample(1.999), Ok(sp(10.0)));
    assert_eq!(b.sample(2.0), Ok(sp(20.0)));
    assert_eq!(b.sample(3.9), Ok(sp(20.0)));
    assert_eq!(b.sample(4.0), Ok(sp(40.0)));
    assert_eq!(b.sample(1e9), Ok(sp(40.0)));

    let mut w = [[0.0; 2]; 6];
    b.window(0.5, 0.75, &mut w).unwrap(); // t = 0.5, 1.25, 2, 2.75, 3.5, 4.25
    assert_eq!(w, [sp(10.0), sp(10.0), sp(20.0), sp(20.0), sp(20.0), sp(40.0)]);
}

#[test]
fn setpoint_linear_interpolation() {
    let mut b: SetpointBuffer<f64, 2, 8> = SetpointBuffer::new(Interpolation::Linear);
    b.push(1.0, sp(10.0)).unwrap();
    b.push(2.0, sp(20.0)).unwrap();
    b.push(4.0, sp(40.0)).unwrap();
    assert_eq!(b.sample(0.0), Ok(sp(10.0)));
    assert_eq!(b.sample(1.0), Ok(sp(10.0)));
    assert_eq!(b.sample(1.5), Ok(sp(15.0)));
    assert_eq!(b.sample(2.0), Ok(sp(20.0)));
    assert_eq!(b.sample(3.0), Ok(sp(30.0)));
    assert_eq!(b.sample(3.5), Ok(sp(35.0)));
    assert_eq!(b.sample(4.0), Ok(sp(40.0)));
    assert_eq!(b.sample(7.0), Ok(sp(40.0))); // after the last: the last

    let mut w = [[0.0; 2]; 5];
    b.window(0.5, 1.0, &mut w).unwrap(); // t = 0.5, 1.5, 2.5, 3.5, 4.5
    assert_eq!(w, [sp(10.0), sp(15.0), sp(25.0), sp(35.0), sp(40.0)]);

    b.set_interpolation(Interpolation::ZeroOrderHold);
    assert_eq!(b.interpolation(), Interpolation::ZeroOrderHold);
    assert_eq!(b.sample(1.5), Ok(sp(10.0)));

    // Endpoints near the top of the range: the interpolation itself would overflow to ∞.
    let mut big: SetpointBuffer<f64, 1, 2> = SetpointBuffer::new(Interpolation::Linear);
    big.push(0.0, [f64::MAX]).unwrap();
    big.push(1.0, [-f64::MAX]).unwrap();
    let v = big.sample(0.5).unwrap()[0];
    assert!(v.is_finite());
}

#[test]
fn setpoint_pop_expired_and_wraparound() {
    let mut b: SetpointBuffer<f64, 2, 3> = SetpointBuffer::new(Interpolation::Linear);
    b.push(1.0, sp(1.0)).unwrap();
    b.push(2.0, sp(2.0)).unwrap();
    b.push(3.0, sp(3.0)).unwrap();
    assert_eq!(b.pop_expired(0.5), 0);
    assert_eq!(b.pop_expired(1.9), 0); // the setpoint at 1 still holds until 2
    assert_eq!(b.pop_expired(2.5), 1);
    assert_eq!(b.iter().map(|(t, _)| *t).collect::<Vec<_>>(), [2.0, 3.0]);
    assert_eq!(b.sample(2.5), Ok(sp(2.5)));
    // Push into the freed slot: the deque wraps around; sampling must follow the logical order.
    b.push(5.0, sp(5.0)).unwrap();
    assert_eq!(b.iter().map(|(t, _)| *t).collect::<Vec<_>>(), [2.0, 3.0, 5.0]);
    assert_eq!(b.sample(4.0), Ok(sp(4.0)));
    assert_eq!(b.sample(2.0), Ok(sp(2.0)));
    let mut w = [[0.0; 2]; 4];
    b.window(1.0, 1.5, &mut w).unwrap(); // 1, 2.5, 4, 5.5
    assert_eq!(w, [sp(2.0), sp(2.5), sp(4.0), sp(5.0)]);
    assert_eq!(b.pop_expired(100.0), 2);
    assert_eq!(b.len(), 1);
    assert_eq!(b.sample(0.0), Ok(sp(5.0)));
    assert_eq!(b.pop_expired(200.0), 0); // the last one is never dropped
    let mut empty: SetpointBuffer<f64, 2, 3> = SetpointBuffer::default();
    assert_eq!(empty.window(0.0, 1.0, &mut w), Err(ReferenceError::Empty));
    assert_eq!(empty.pop_expired(1.0), 0);
}

// ---------------------------------------------------------------- controller

type Ctrl<Src, C = NoCycleCounter> = Controller<FakeSolver, Src, f64, NX, NU, N1, C>;

fn circular_window(t0: f64) -> [[f64; NX]; N1] {
    let mut w = [[0.0; NX]; N1];
    ReferenceSource::<f64, NX, N1>::window(&mut Trajectory::Circular, t0, DT, &mut w).unwrap();
    w
}

#[test]
fn timeline_prepare_feedback_shift() {
    let u = [1.0, 0.1, -0.2, 0.3];
    let mut c: Ctrl<Trajectory> = Controller::new(FakeSolver::new(u), Trajectory::Circular);
    assert!(!c.is_prepared());
    assert_eq!(c.start(1.0), Ok(Status::Solved));
    assert!(c.is_prepared());
    assert_eq!(c.solver().events, [Event::Prepare]);
    assert_eq!(c.solver().references[0], circular_window(1.0));
    assert_eq!(c.reference_window(), &circular_window(1.0));

    let x = [0.5; NX];
    let sol = c.feedback(&x).unwrap();
    assert_eq!(
        sol,
        Solution {
            u0: u,
            status: Status::Solved,
            qp_iterations: 3,
            cost: 1.5
        }
    );
    assert_eq!(c.solver().states, [x]);
    assert_eq!(c.last_input(), &u);
    assert!(!c.is_prepared());
    // Nothing else happened in feedback: the preparation is the next call's job.
    assert_eq!(c.solver().events, [Event::Prepare, Event::Feedback]);

    assert_eq!(c.prepare_next(), Ok(Status::Solved));
    assert_eq!(
        c.solver().events,
        [Event::Prepare, Event::Feedback, Event::Shift, Event::Prepare]
    );
    assert_close(c.time(), 1.1, 1e-15);
    assert_eq!(c.step_count(), 1);
    assert_eq!(c.solver().references[1], circular_window(1.0 + DT));

    // step = feedback + prepare_next; after 10 more the time is t0 + 11 DT (no drift).
    // (A moving measurement that changes: a repeated one would be reported stale after 0.5 s.)
    for i in 0..10 {
        let mut xi = x;
        xi[0] += 0.01 * f64::from(i + 1);
        c.step(&xi).unwrap();
    }
    assert_eq!(c.step_count(), 11);
    assert_eq!(c.time(), 1.0 + 11.0 * DT);
    assert_eq!(c.solver().references.last().unwrap(), &circular_window(1.0 + 11.0 * DT));
    let ev = &c.solver().events;
    assert_eq!(ev.len(), 4 + 10 * 3);
    assert_eq!(ev[ev.len() - 3..], [Event::Feedback, Event::Shift, Event::Prepare]);
    assert_eq!(c.last_prepare_status(), Some(Status::Solved));
}

#[test]
fn feedback_without_start_prepares_at_time_zero() {
    let mut c: Ctrl<Trajectory> = Controller::new(FakeSolver::new([0.0; NU]), Trajectory::Spiral);
    c.feedback(&[0.0; NX]).unwrap();
    assert_eq!(c.solver().events, [Event::Prepare, Event::Feedback]);
    let mut w = [[0.0; NX]; N1];
    ReferenceSource::<f64, NX, N1>::window(&mut Trajectory::Spiral, 0.0, DT, &mut w).unwrap();
    assert_eq!(c.solver().references[0], w);
    // A second feedback without prepare_next prepares again at the same time (an SQP iteration).
    c.feedback(&[0.0; NX]).unwrap();
    assert_eq!(
        c.solver().events,
        [Event::Prepare, Event::Feedback, Event::Prepare, Event::Feedback]
    );
    assert_eq!(c.solver().references[1], w);
    // initialize invalidates the preparation.
    c.prepare_next().unwrap();
    c.initialize(&[0.0; NX], &[0.0; NU]);
    assert!(!c.is_prepared());
    c.feedback(&[0.0; NX]).unwrap();
    assert_eq!(
        c.solver().events[6..],
        [Event::Initialize, Event::Prepare, Event::Feedback]
    );
}

#[test]
fn timings_are_recorded() {
    // Reads: prepare start/end, feedback start/end, ...
    let counter = StepCounter {
        now: u32::MAX - 50,
        steps: std::vec![10, 1000, 7, 300],
        reads: 0,
    };
    let mut c: Ctrl<Trajectory, StepCounter> =
        Controller::with_counter(FakeSolver::new([0.0; NU]), Trajectory::Circular, counter);
    c.start(0.0).unwrap(); // 1000 cycles (across the wrap of the counter)
    c.feedback(&[0.0; NX]).unwrap(); // 300
    c.prepare_next().unwrap(); // 1000
    c.feedback(&[0.0; NX]).unwrap(); // 300
    let t = c.timings();
    assert_eq!(
        t.prepare,
        CycleStats {
            last: 1000,
            max: 1000,
            count: 2
        }
    );
    assert_eq!(
        t.feedback,
        CycleStats {
            last: 300,
            max: 300,
            count: 2
        }
    );

    c.counter_mut().steps = std::vec![1, 20, 1, 5];
    c.counter_mut().reads = 0;
    c.prepare_next().unwrap(); // 20
    c.feedback(&[0.0; NX]).unwrap(); // 5
    let t = c.timings();
    assert_eq!(
        t.prepare,
        CycleStats {
            last: 20,
            max: 1000,
            count: 3
        }
    );
    assert_eq!(
        t.feedback,
        CycleStats {
            last: 5,
            max: 300,
            count: 3
        }
    );
    c.reset_timings();
    assert_eq!(c.timings(), Timings::default());

    // Closures are counters; NoCycleCounter reads 0.
    let mut n = 0u32;
    let mut c2 = Controller::with_counter(FakeSolver::new([0.0; NU]), Trajectory::Circular, move || {
        n += 4;
        n
    });
    c2.step(&[0.0; NX]).unwrap();
    assert_eq!(c2.timings().feedback.last, 4);
    let mut c3: Ctrl<Trajectory> = Controller::new(FakeSolver::new([0.0; NU]), Trajectory::Circular);
    c3.step(&[0.0; NX]).unwrap();
    assert_eq!(
        c3.timings().prepare,
        CycleStats {
            last: 0,
            max: 0,
            count: 2
        }
    );
}

#[test]
fn nan_state_keeps_previous_plan_and_reports_it() {
    let u = [1.0, 0.1, -0.2, 0.3];
    let mut c: Ctrl<Trajectory> = Controller::new(FakeSolver::new(u), Trajectory::Circular);
    c.start(0.0).unwrap();
    c.step(&[0.0; NX]).unwrap();
    c.solver_mut().u = [2.0, 0.3, 0.3, 2.0]; // would be the new input, but the state is invalid
    let mut x = [0.0; NX];
    x[4] = f64::NAN;
    let err = c.feedback(&x).unwrap_err();
    assert_eq!(err.kind, ControlErrorKind::InvalidState);
    assert_eq!(err.solution.status, Status::InvalidInput);
    assert_eq!(err.input(), &u); // the previous plan's first input
    assert_eq!(c.last_input(), &u);
    // The solver saw the NaN state (its InvalidInput behaviour applies).
    assert!(c.solver().states.last().unwrap()[4].is_nan());
    x[4] = f64::INFINITY;
    assert_eq!(c.step(&x).unwrap_err().kind, ControlErrorKind::InvalidState);
    // Recovery.
    assert_eq!(c.feedback(&[0.0; NX]).unwrap().u0, [2.0, 0.3, 0.3, 2.0]);
}

/// A solver whose outputs are set by the test.
struct Scripted {
    solution: Solution<f64, NU>,
}

impl MpcSolver<f64, NX, NU, N1> for Scripted {
    const DT: f64 = DT;
    const U_MIN: [f64; NU] = U_MIN;
    const U_MAX: [f64; NU] = U_MAX;
    fn initialize(&mut self, _x0: &[f64; NX], _u: &[f64; NU]) {}
    fn prepare(&mut self, _reference: &[[f64; NX]; N1]) -> Status {
        Status::Solved
    }
    fn feedback(&mut self, _x0: &[f64; NX]) -> Solution<f64, NU> {
        self.solution
    }
    fn shift(&mut self) {}
}

#[test]
fn solver_output_is_sanitised() {
    let good = Solution {
        u0: [1.0, 0.2, -0.3, 0.4],
        status: Status::Solved,
        qp_iterations: 2,
        cost: 1.0,
    };
    let mut c = Controller::new(Scripted { solution: good }, Trajectory::Circular);
    // Before any feedback the fallback is 0 (within these bounds).
    assert_eq!(c.last_input(), &[0.0; NU]);
    assert_eq!(c.step(&[0.0; NX]), Ok(good));

    // Non-finite entries: replaced by the last input's.
    c.solver_mut().solution.u0 = [f64::NAN, 0.1, f64::INFINITY, 0.0];
    let e = c.step(&[0.0; NX]).unwrap_err();
    assert_eq!(e.kind, ControlErrorKind::NonFiniteInput);
    assert_eq!(e.solution.u0, [1.0, 0.1, -0.3, 0.0]);

    // Out of bounds: clamped.
    c.solver_mut().solution.u0 = [9.0, -1.0, 0.0, 0.0];
    let e = c.step(&[0.0; NX]).unwrap_err();
    assert_eq!(e.kind, ControlErrorKind::InputClamped);
    assert_eq!(e.solution.u0, [5.0, -0.611, 0.0, 0.0]);

    // Solver statuses.
    c.solver_mut().solution = Solution {
        status: Status::NumericalFailure,
        ..good
    };
    assert_eq!(c.step(&[0.0; NX]).unwrap_err().kind, ControlErrorKind::NumericalFailure);
    c.solver_mut().solution = Solution {
        status: Status::InvalidInput,
        ..good
    };
    assert_eq!(
        c.step(&[0.0; NX]).unwrap_err().kind,
        ControlErrorKind::SolverInvalidInput
    );
    for status in [Status::IterationCap, Status::HessianRegularised] {
        c.solver_mut().solution = Solution { status, ..good };
        assert_eq!(c.step(&[0.0; NX]).unwrap().status, status);
    }
    // A NaN cost is reported as +∞.
    c.solver_mut().solution = Solution { cost: f64::NAN, ..good };
    assert_eq!(c.step(&[0.0; NX]).unwrap().cost, f64::INFINITY);
}

/// Bounds that exclude 0: the neutral input is clamped into them.
struct Offset;

impl MpcSolver<f32, 2, 2, 3> for Offset {
    const DT: f32 = 0.5;
    const U_MIN: [f32; 2] = [1.0, -3.0];
    const U_MAX: [f32; 2] = [2.0, -2.0];
    fn initialize(&mut self, _x0: &[f32; 2], _u: &[f32; 2]) {}
    fn prepare(&mut self, _reference: &[[f32; 2]; 3]) -> Status {
        Status::Solved
    }
    fn feedback(&mut self, _x0: &[f32; 2]) -> Solution<f32, 2> {
        Solution {
            u0: [f32::NAN; 2],
            status: Status::NumericalFailure,
            qp_iterations: 0,
            cost: f32::NAN,
        }
    }
    fn shift(&mut self) {}
}

#[test]
fn no_reference_means_not_prepared() {
    let mut c = Controller::new(Offset, SetpointBuffer::<f32, 2, 4>::default());
    assert_eq!(c.start(0.0), Err(ReferenceError::Empty));
    let e = c.feedback(&[0.0; 2]).unwrap_err();
    assert_eq!(e.kind, ControlErrorKind::NotPrepared);
    assert_eq!(e.solution.u0, [1.0, -2.0]);
    assert_eq!(c.prepare_next(), Err(ReferenceError::Empty));
    assert_eq!(c.last_prepare_status(), None);
    // A setpoint arrives: the next preparation uses it.
    c.reference_mut().push(0.0, [3.0, 4.0]).unwrap();
    assert_eq!(c.prepare_next(), Ok(Status::Solved));
    assert_eq!(c.reference_window(), &[[3.0, 4.0]; 3]);
    // This solver returns NaN inputs: replaced by the last input, never NaN.
    let e = c.feedback(&[0.0; 2]).unwrap_err();
    assert_eq!(e.kind, ControlErrorKind::NonFiniteInput);
    assert_eq!(e.solution.u0, [1.0, -2.0]);
    assert_eq!(e.solution.cost, f32::INFINITY);
}

#[test]
fn reference_failure_falls_back_to_shifted_window() {
    let mut buffer: SetpointBuffer<f64, NX, 8> = SetpointBuffer::new(Interpolation::Linear);
    let target = |v: f64| {
        let mut x = [0.0; NX];
        x[0] = v;
        x
    };
    buffer.push(0.0, target(0.0)).unwrap();
    buffer.push(3.0, target(30.0)).unwrap();
    let mut c: Ctrl<SetpointBuffer<f64, NX, 8>> = Controller::new(FakeSolver::new([0.0; NU]), buffer);
    c.start(0.0).unwrap();
    let first = c.solver().references[0];
    for (k, row) in first.iter().enumerate() {
        assert_close(row[0], if k <= 30 { 10.0 * k as f64 * DT } else { 30.0 }, 1e-12);
    }
    c.feedback(&[0.0; NX]).unwrap();
    c.reference_mut().clear();
    assert_eq!(c.prepare_next(), Err(ReferenceError::Empty));
    // The solver was still shifted and prepared, with the previous window shifted by one sample.
    assert_eq!(c.solver().events[2..], [Event::Shift, Event::Prepare]);
    let second = c.solver().references[1];
    assert_eq!(second[..30], first[1..]);
    assert_eq!(second[30], first[30]);
    // step reports the preparation's reference error with a valid solution.
    let e = c.step(&[0.0; NX]).unwrap_err();
    assert_eq!(e.kind, ControlErrorKind::Reference(ReferenceError::Empty));
    assert_eq!(e.solution.status, Status::Solved);
    assert!(c.is_prepared());
}

#[test]
fn non_finite_reference_values_never_reach_the_solver() {
    let src = FnReference(|t: f64| {
        let mut x = [0.0; NX];
        x[2] = if t > 0.25 { f64::NAN } else { 6.0 };
        x
    });
    let mut c: Ctrl<_> = Controller::new(FakeSolver::new([0.0; NU]), src);
    // The first window already has NaN rows (t > 0.25) and there is no earlier one.
    assert_eq!(c.start(0.0), Err(ReferenceError::NonFinite));
    assert!(c.solver().references.is_empty());
    assert_eq!(c.feedback(&[0.0; NX]).unwrap_err().kind, ControlErrorKind::NotPrepared);
    assert!(c.solver().events.is_empty());
}

#[test]
fn controller_borrows_a_solver() {
    let mut solver = FakeSolver::new([0.5; NU]);
    {
        let mut c = Controller::new(&mut solver, Trajectory::Sinusoidal);
        assert_eq!(Controller::<&mut FakeSolver, Trajectory, f64, NX, NU, N1>::DT, DT);
        c.start(0.0).unwrap();
        c.step(&[0.0; NX]).unwrap();
        let (s, tr, _) = c.into_parts();
        assert_eq!(tr, Trajectory::Sinusoidal);
        assert_eq!(s.events.len(), 4);
    }
    assert_eq!(
        solver.events,
        [Event::Prepare, Event::Feedback, Event::Shift, Event::Prepare]
    );
}

#[test]
fn errors_display() {
    extern crate alloc;
    use alloc::string::ToString;
    let e = ControlError {
        kind: ControlErrorKind::Reference(ReferenceError::Empty),
        solution: Solution {
            u0: [0.0f64; 1],
            status: Status::Solved,
            qp_iterations: 0,
            cost: 0.0,
        },
    };
    assert_eq!(
        e.to_string(),
        "next reference window: no setpoint (solver status: solved)"
    );
    assert_eq!(SetpointError::Full.to_string(), "setpoint buffer full");
    assert!(Status::HessianRegularised.is_usable());
    assert!(!Status::InvalidInput.is_usable());
}

// ---------------------------------------------------------------- mpc_adapter!

/// The generated MPC API of docs/mpc.md, as a module (f32, NX = 12, NU = 4, N = 5).
#[allow(dead_code)]
mod fake_generated {
    pub type Real = f32;
    pub const NX: usize = 12;
    pub const NU: usize = 4;
    pub const N: usize = 5;
    pub const DT: Real = 0.05;
    pub const U_MIN: [Real; NU] = [-5.0, -0.611, -0.611, -2.618];
    pub const U_MAX: [Real; NU] = [5.0, 0.611, 0.611, 2.618];

    pub enum Status {
        Solved,
        IterationCap,
        HessianRegularised,
        InvalidInput,
        NumericalFailure,
        #[allow(dead_code)]
        OutOfEnvelope,
    }

    pub struct Solution {
        pub u0: [Real; NU],
        pub status: Status,
        pub qp_iterations: usize,
        pub cost: Real,
    }

    pub struct Mpc {
        pub inputs: [[Real; NU]; N],
        pub states: [[Real; NX]; N + 1],
        pub reference: [[Real; NX]; N + 1],
        pub shifts: usize,
        pub calls: usize,
        pub disturbance: [Real; NX],
    }

    impl Mpc {
        pub const fn new() -> Self {
            Self {
                inputs: [[0.0; NU]; N],
                states: [[0.0; NX]; N + 1],
                reference: [[0.0; NX]; N + 1],
                shifts: 0,
                calls: 0,
                disturbance: [0.0; NX],
            }
        }
        pub fn initialize(&mut self, x0: &[Real; NX], u: &[Real; NU]) {
            self.states = [*x0; N + 1];
            self.inputs = [*u; N];
        }
        pub fn prepare(&mut self, reference: &[[Real; NX]; N + 1]) -> Status {
            self.reference = *reference;
            Status::HessianRegularised
        }
        pub fn feedback(&mut self, x0: &[Real; NX]) -> Solution {
            self.calls += 1;
            self.states[0] = *x0;
            let status = match self.calls % 5 {
                0 => Status::Solved,
                1 => Status::IterationCap,
                2 => Status::HessianRegularised,
                3 => Status::InvalidInput,
                _ => Status::NumericalFailure,
            };
            Solution {
                u0: self.inputs[0],
                status,
                qp_iterations: self.calls,
                cost: 0.25,
            }
        }
        pub fn shift(&mut self) {
            self.shifts += 1;
        }
        pub fn set_disturbance(&mut self, e: &[Real; NX]) -> bool {
            self.disturbance = *e;
            true
        }
        pub fn planned_inputs(&self) -> &[[Real; NU]; N] {
            &self.inputs
        }
        pub fn predicted_states(&self) -> &[[Real; NX]; N + 1] {
            &self.states
        }
    }
}

crate::mpc_adapter!(
    /// An adapter defined by the macro.
    struct FakeAdapter(fake_generated);
);

#[test]
fn mpc_adapter_forwards_and_converts() {
    fn assert_solver<S: MpcSolver<f32, 12, 4, 6>>(_: &S) {}
    let mut a = FakeAdapter::default();
    assert_solver(&a);
    assert_eq!(<FakeAdapter as MpcSolver<f32, 12, 4, 6>>::DT, 0.05);
    assert_eq!(<FakeAdapter as MpcSolver<f32, 12, 4, 6>>::U_MAX, fake_generated::U_MAX);
    a.initialize(&[1.0; 12], &[0.5, 0.1, 0.0, 0.0]);
    assert_eq!(a.planned_inputs()[4], [0.5, 0.1, 0.0, 0.0]);
    assert_eq!(a.predicted_states()[5], [1.0; 12]);
    assert_eq!(a.prepare(&[[2.0; 12]; 6]), Status::HessianRegularised);
    assert_eq!(a.inner().reference, [[2.0; 12]; 6]);
    let expected = [
        Status::IterationCap,
        Status::HessianRegularised,
        Status::InvalidInput,
        Status::NumericalFailure,
        Status::Solved,
    ];
    for (i, status) in expected.into_iter().enumerate() {
        let s = MpcSolver::feedback(&mut a, &[0.0; 12]);
        assert_eq!(
            s,
            Solution {
                u0: [0.5, 0.1, 0.0, 0.0],
                status,
                qp_iterations: i + 1,
                cost: 0.25
            }
        );
    }
    MpcSolver::shift(&mut a);
    a.inner_mut().calls = 4;
    assert_eq!(a.into_inner().shifts, 1);

    // Through the controller, f32 end to end.
    let mut adapter = FakeAdapter::new();
    let mut c = Controller::new(&mut adapter, Trajectory::Circular);
    assert_eq!(c.start(0.0), Ok(Status::HessianRegularised));
    assert_eq!(c.feedback(&[0.0; 12]).map(|s| s.status), Ok(Status::IterationCap));
    c.prepare_next().unwrap();
    assert_close(c.time(), 0.05, 1e-7);
    let w: [[f32; 12]; 6] = *c.reference_window();
    assert_eq!(adapter.inner().reference, w);
    assert_eq!(adapter.inner().shifts, 1);
}

/// Records the disturbance it was told at every `prepare`.
struct DisturbedSolver {
    told: [f64; NX],
    prepared_with: Vec<[f64; NX]>,
}

impl MpcSolver<f64, NX, NU, N1> for DisturbedSolver {
    const DT: f64 = DT;
    const U_MIN: [f64; NU] = U_MIN;
    const U_MAX: [f64; NU] = U_MAX;
    fn initialize(&mut self, _x0: &[f64; NX], _u: &[f64; NU]) {}
    fn prepare(&mut self, _reference: &[[f64; NX]; N1]) -> Status {
        self.prepared_with.push(self.told);
        Status::Solved
    }
    fn feedback(&mut self, _x0: &[f64; NX]) -> Solution<f64, NU> {
        Solution {
            u0: [0.0; NU],
            status: Status::Solved,
            qp_iterations: 1,
            cost: 0.0,
        }
    }
    fn shift(&mut self) {}
    fn set_disturbance(&mut self, e: &[f64; NX]) -> bool {
        self.told = *e;
        true
    }
}

#[test]
fn the_controller_tells_the_solver_the_observers_disturbance() {
    // The model says the state stays put; the aircraft's vx grows by 0.05 m/s every sample (a
    // constant 0.5 m/s² the model lacks), and every third measurement repeats the one before.
    let model = |x: &[f64; NX], _u: &[f64; NU]| *x;
    let mut bound = [0.0; NX];
    bound[6] = 0.1;
    let predictor = DelayCompensator::<f64, _, NX, NU, 4>::new(model, [2, 1, 1, 3], [0.0; NU])
        .unwrap()
        .with_disturbance_observer(0.5, bound);
    let solver = DisturbedSolver {
        told: [f64::NAN; NX],
        prepared_with: Vec::new(),
    };
    let mut c = Controller::new(solver, ConstantReference([0.0; NX])).with_delay_compensation(predictor);
    c.start(0.0).unwrap();
    let mut x = [0.0; NX];
    let mut shown = x;
    for k in 0..60 {
        if k % 3 != 2 {
            shown = x;
        }
        c.feedback(&shown).unwrap();
        c.prepare_next().unwrap();
        x[6] += 0.05;
    }
    let told = c.solver().prepared_with.last().copied().unwrap();
    assert!((told[6] - 0.05).abs() < 1e-9, "told {told:?}");
    assert!(told.iter().enumerate().all(|(i, v)| i == 6 || *v == 0.0));
    // The prediction over the shared delay (1 sample) includes it.
    let e = c.delay_compensator().disturbance().unwrap();
    assert_eq!(e[6], told[6]);
    // Without an observer the solver is never told anything.
    let plain = DelayCompensator::<f64, _, NX, NU, 4>::new(model, [0; NU], [0.0; NU])
        .unwrap()
        .with_disturbance_observer(0.0, bound);
    assert!(plain.observer().is_none() && plain.disturbance().is_none());
}

/// Supervisor: an input at its bound in every sample while the position error does not shrink is
/// reported as `NotConverging` after one window; shrinking fast enough is not.
#[test]
fn saturation_without_progress_is_reported() {
    let supervision = Supervision {
        stale_after: 0.5,
        window: 1.0,
        min_closing_speed: 0.2,
    };
    // The fake solver's input has u_vz at its bound.
    for (closing_speed, expect) in [(0.0, true), (0.1, true), (1.0, false)] {
        let mut c = Controller::new(FakeSolver::new([5.0, 0.0, 0.0, 0.0]), ConstantReference([0.0; NX]))
            .with_supervision(supervision);
        c.start(0.0).unwrap();
        let mut reported = Vec::new();
        for k in 0..40 {
            // 20 m away, closing at `closing_speed`; zero velocity (never stale).
            let x = {
                let mut x = [0.0; NX];
                x[0] = 20.0 - closing_speed * k as f64 * DT;
                x
            };
            reported.push(c.feedback(&x).err().map(|e| e.kind));
            c.prepare_next().unwrap();
        }
        // The window (10 samples) closes at k = 10: from then on the verdict stands.
        assert!(reported[..10].iter().all(|k| k.is_none()), "{reported:?}");
        let flagged = reported[10..]
            .iter()
            .all(|k| *k == Some(ControlErrorKind::NotConverging));
        let clean = reported[10..].iter().all(|k| k.is_none());
        assert!(
            if expect { flagged } else { clean },
            "speed {closing_speed}: {reported:?}"
        );
        assert_eq!(c.supervision().not_converging, expect);
    }
    // Off the bound the flag clears at once.
    let mut c = Controller::new(FakeSolver::new([5.0, 0.0, 0.0, 0.0]), ConstantReference([0.0; NX]))
        .with_supervision(supervision);
    c.start(0.0).unwrap();
    let mut x = [0.0; NX];
    x[0] = 20.0;
    for _ in 0..12 {
        let _ = c.feedback(&x);
        c.prepare_next().unwrap();
    }
    assert!(c.supervision().not_converging);
    c.solver_mut().u = [4.0, 0.0, 0.0, 0.0];
    assert!(c.feedback(&x).is_ok());
    assert!(!c.supervision().not_converging);
}

/// Supervisor: a moving aircraft's measurement repeated bit for bit longer than `stale_after` is
/// reported; at rest (zero velocity) a repeated value is normal; a fresh value clears it.
#[test]
fn a_held_measurement_is_reported_as_stale() {
    let mut c = Controller::new(FakeSolver::new([0.0; NU]), ConstantReference([0.0; NX]));
    c.start(0.0).unwrap();
    let mut moving = [0.0; NX];
    moving[6] = 1.0;
    let mut kinds = Vec::new();
    for _ in 0..10 {
        kinds.push(c.feedback(&moving).err().map(|e| e.kind));
        c.prepare_next().unwrap();
    }
    // 0.5 s at DT = 0.1: held for 0.1, …, 0.5 s is fine, 0.6 s is stale.
    assert!(kinds[..6].iter().all(|k| k.is_none()), "{kinds:?}");
    assert!(
        kinds[6..]
            .iter()
            .all(|k| *k == Some(ControlErrorKind::StaleMeasurement)),
        "{kinds:?}"
    );
    assert!(c.supervision().stale && c.supervision().held_for > 0.5);
    moving[0] = 0.1;
    assert!(c.feedback(&moving).is_ok());
    assert!(!c.supervision().stale);
    let at_rest = [0.0; NX];
    for _ in 0..20 {
        assert!(c.feedback(&at_rest).is_ok());
        c.prepare_next().unwrap();
    }
}

/// Time: `feedback_at` catches up over the samples whose `prepare_next` did not happen (shifts,
/// reference time), counts and reports them; `start(t)` again shifts like `prepare_next`.
#[test]
fn missed_deadlines_are_caught_up_and_counted() {
    let mut c = Controller::new(FakeSolver::new([0.0; NU]), Trajectory::Circular);
    c.start(1.0).unwrap();
    assert!(c.feedback_at(1.0, &[0.0; NX]).is_ok());
    // No prepare_next: the next measurement comes 3 samples later.
    let e = c.feedback_at(1.0 + 3.0 * DT, &[0.0; NX]).unwrap_err();
    assert_eq!(e.kind, ControlErrorKind::DeadlineMissed);
    assert_eq!(c.supervision().deadline_misses, 3);
    assert_eq!(c.step_count(), 3);
    assert_close(c.time(), 1.3, 1e-12);
    let shifts = c.solver().events.iter().filter(|e| **e == Event::Shift).count();
    assert_eq!(shifts, 3);
    let last = c.solver().references.last().unwrap();
    assert_close(last[0][0], 5.0 * 1.3f64.cos(), 1e-12);
    // On time: no miss.
    c.prepare_next().unwrap();
    assert!(c.feedback_at(1.4, &[0.0; NX]).is_ok());
    assert_eq!(c.supervision().deadline_misses, 3);

    // start(t) each period = prepare_next.
    let mut a = Controller::new(FakeSolver::new([0.0; NU]), Trajectory::Circular);
    let mut b = Controller::new(FakeSolver::new([0.0; NU]), Trajectory::Circular);
    a.start(0.0).unwrap();
    b.start(0.0).unwrap();
    for k in 1..20 {
        let _ = a.feedback(&[0.0; NX]);
        let _ = b.feedback(&[0.0; NX]);
        a.prepare_next().unwrap();
        b.start(k as f64 * DT).unwrap();
    }
    assert_eq!(a.solver().events, b.solver().events);
    assert_close(a.time(), b.time(), 1e-12);
    assert_close(a.reference_window()[0][0], b.reference_window()[0][0], 1e-12);
}

/// Time is kept in f64: an f32 controller at Unix time still steps its reference window.
#[test]
fn f32_controllers_keep_time_at_unix_epochs() {
    let mut c = Controller::new(Offset, Trajectory::Circular);
    c.start(1.7e9).unwrap();
    for _ in 0..3 {
        let _ = c.feedback(&[0.0; 2]);
        c.prepare_next().unwrap();
    }
    let t = 1.7e9 + 3.0 * f64::from(<Offset as MpcSolver<f32, 2, 2, 3>>::DT);
    assert_close(c.time(), t, 1e-15);
    let w = c.reference_window();
    for (k, row) in w.iter().enumerate() {
        let tk = t + k as f64 * f64::from(<Offset as MpcSolver<f32, 2, 2, 3>>::DT);
        assert!((f64::from(row[0]) - 5.0 * tk.cos()).abs() < 1e-5, "row {k}");
    }
    assert_ne!(w[0], w[1]);
}
