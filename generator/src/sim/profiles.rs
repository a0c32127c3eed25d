//! Flight profiles: what the pilot does in a segment (docs/simulate.md).
//!
//! - `excite`: rich excitation for identification. Multisines (10 log-spaced frequencies from
//!   0.05 to 2.5 Hz, random phases) plus random steps (held 0.5–3 s) on all four inputs, on top of
//!   a weak position/altitude-keeping loop towards random waypoints (|x|, |y| ≤ 4 m, z 1.5–10 m,
//!   one in four a low pass at z 0.1–0.4 m for ground effect; a new one every 4–8 s). The tilt
//!   √(roll² + pitch²) of the command is limited to 0.35 rad, the horizontal velocity reference
//!   to 2.5 m/s. Starts at (0, 0, 3), random heading.
//! - `excite-hold-heading`: `excite` with the heading held at its random start (no yaw-rate
//!   excitation, no new heading per waypoint; only the weak heading loop commands u_yaw_rate): the
//!   flights of an aircraft whose pilot never turns, whose heading and yaw channel carry no signal.
//! - `hover`: hold (3, 3, 5) with small random disturbances on all inputs.
//! - `circle`, `sinusoid`, `spiral`: the paper's trajectories (MODEL_NOTES.md), tracked by the
//!   position loop with velocity and acceleration feed-forward, heading 0, from (3, 3, 5).

use super::error::PlantError;
use super::outer_loop::{OuterLoop, Reference};
use super::plant::wrap_angle;
use super::rng::{Random, Stream};
use std::fmt;
use std::str::FromStr;

/// A flight profile.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Profile {
    Excite,
    ExciteHoldHeading,
    Hover,
    Circle,
    Sinusoid,
    Spiral,
}

impl Profile {
    pub const ALL: [Profile; 6] = [
        Profile::Excite,
        Profile::ExciteHoldHeading,
        Profile::Hover,
        Profile::Circle,
        Profile::Sinusoid,
        Profile::Spiral,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Profile::Excite => "excite",
            Profile::ExciteHoldHeading => "excite-hold-heading",
            Profile::Hover => "hover",
            Profile::Circle => "circle",
            Profile::Sinusoid => "sinusoid",
            Profile::Spiral => "spiral",
        }
    }

    /// A comma-separated list (`excite,circle`).
    pub fn parse_list(text: &str) -> Result<Vec<Profile>, PlantError> {
        let list: Result<Vec<Profile>, PlantError> = text.split(',').map(|s| s.trim().parse()).collect();
        let list = list?;
        Ok(list)
    }

    /// The start state (log order).
    pub fn start(self, rng: &mut Random) -> [f64; 12] {
        let mut x = [0.0; 12];
        match self {
            Profile::Excite | Profile::ExciteHoldHeading => {
                x[2] = 3.0;
                x[5] = rng.range(-std::f64::consts::PI, std::f64::consts::PI);
            }
            _ => {
                x[0] = 3.0;
                x[1] = 3.0;
                x[2] = 5.0;
            }
        }
        x
    }

    /// The paper's reference at time t (s from the segment start), for the trajectories.
    pub fn trajectory(self, t: f64) -> Option<Reference> {
        let (p, v, a) = match self {
            Profile::Sinusoid => {
                let (s1, c1) = (0.32 * t).sin_cos();
                let (s2, c2) = (0.64 * t).sin_cos();
                (
                    [4.0 * s1 + 3.0, 4.0 * s2, 2.0 * s2 + 6.0],
                    [4.0 * 0.32 * c1, 4.0 * 0.64 * c2, 2.0 * 0.64 * c2],
                    [
                        -4.0 * 0.32 * 0.32 * s1,
                        -4.0 * 0.64 * 0.64 * s2,
                        -2.0 * 0.64 * 0.64 * s2,
                    ],
                )
            }
            Profile::Circle => {
                let (s, c) = t.sin_cos();
                (
                    [5.0 * c, 5.0 * s, 6.0],
                    [-5.0 * s, 5.0 * c, 0.0],
                    [-5.0 * c, -5.0 * s, 0.0],
                )
            }
            Profile::Spiral => {
                let e = (0.06 * t).exp();
                let (s, c) = t.sin_cos();
                // d/dt e^{kt} cos t = e^{kt} (k cos t − sin t); twice: e^{kt} ((k² − 1) cos t − 2k sin t).
                let k = 0.06;
                (
                    [e * c, e * s, 0.1 * t + 5.0],
                    [e * (k * c - s), e * (k * s + c), 0.1],
                    [
                        e * ((k * k - 1.0) * c - 2.0 * k * s),
                        e * ((k * k - 1.0) * s + 2.0 * k * c),
                        0.0,
                    ],
                )
            }
            Profile::Excite | Profile::ExciteHoldHeading | Profile::Hover => return None,
        };
        Some(Reference {
            p,
            v,
            a,
            yaw: 0.0,
            yaw_rate: 0.0,
        })
    }
}

impl fmt::Display for Profile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Profile {
    type Err = PlantError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Profile::ALL.into_iter().find(|p| p.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Profile::ALL.iter().map(|p| p.name()).collect();
            PlantError::option(
                "--profile",
                format!("unknown profile `{s}`: expected one of {}", names.join(", ")),
            )
        })
    }
}

/// A sum of sines with random phases.
#[derive(Clone, Debug)]
struct Multisine {
    parts: Vec<(f64, f64, f64)>,
}

impl Multisine {
    /// `n` log-spaced frequencies in [f_lo, f_hi] Hz, total RMS `rms`.
    fn new(rng: &mut Random, n: usize, f_lo: f64, f_hi: f64, rms: f64) -> Self {
        let amp = rms * (2.0 / n as f64).sqrt();
        let parts = (0..n)
            .map(|k| {
                let f = f_lo * (f_hi / f_lo).powf(k as f64 / (n - 1).max(1) as f64);
                (amp, std::f64::consts::TAU * f, rng.range(0.0, std::f64::consts::TAU))
            })
            .collect();
        Self { parts }
    }

    fn at(&self, t: f64) -> f64 {
        self.parts.iter().map(|(a, w, phi)| a * (w * t + phi).sin()).sum()
    }
}

/// Random steps held for a random time.
#[derive(Clone, Debug)]
struct Steps {
    amplitude: f64,
    hold: (f64, f64),
    value: f64,
    until: f64,
}

impl Steps {
    fn new(amplitude: f64, hold: (f64, f64)) -> Self {
        Self {
            amplitude,
            hold,
            value: 0.0,
            until: 0.0,
        }
    }

    fn at(&mut self, t: f64, rng: &mut Random) -> f64 {
        if t >= self.until {
            self.value = rng.range(-self.amplitude, self.amplitude);
            self.until = t + rng.range(self.hold.0, self.hold.1);
        }
        self.value
    }
}

/// Excitation on the four inputs: multisine + steps, each scaled per channel.
#[derive(Clone, Debug)]
struct Excitation {
    sines: Vec<Multisine>,
    steps: Vec<Steps>,
}

impl Excitation {
    /// `rms[i]`: multisine RMS; `step[i]`: step amplitude of channel i (u_vz, u_roll, u_pitch, u_yaw_rate).
    fn new(rng: &mut Random, rms: [f64; 4], step: [f64; 4]) -> Self {
        Self {
            sines: rms.iter().map(|r| Multisine::new(rng, 10, 0.05, 2.5, *r)).collect(),
            steps: step.iter().map(|a| Steps::new(*a, (0.5, 3.0))).collect(),
        }
    }

    fn at(&mut self, t: f64, rng: &mut Random) -> [f64; 4] {
        let mut e = [0.0; 4];
        for i in 0..4 {
            e[i] = self.sines[i].at(t) + self.steps[i].at(t, rng);
        }
        e
    }
}

/// Excite: tilt clamp, horizontal speed reference limit.
pub const EXCITE_MAX_TILT: f64 = 0.35;
pub const EXCITE_MAX_SPEED_REF: f64 = 2.5;

/// A profile being flown: gives the command for each sample.
#[derive(Clone, Debug)]
pub struct Pilot {
    profile: Profile,
    rng: Random,
    outer: OuterLoop,
    excitation: Option<Excitation>,
    start: [f64; 12],
    waypoint: [f64; 3],
    heading: f64,
    next_waypoint: f64,
}

impl Pilot {
    /// The pilot of segment `index` of a run with `seed`.
    pub fn new(profile: Profile, seed: u64, index: u64, gravity: f64) -> Self {
        let mut rng = Random::new(seed, Stream::Profile, index);
        let start = profile.start(&mut rng);
        let excitation = match profile {
            Profile::Excite => Some(Excitation::new(&mut rng, [0.4, 0.06, 0.06, 0.2], [0.7, 0.1, 0.1, 0.4])),
            Profile::ExciteHoldHeading => Some(Excitation::new(&mut rng, [0.4, 0.06, 0.06, 0.0], [0.7, 0.1, 0.1, 0.0])),
            Profile::Hover => Some(Excitation::new(&mut rng, [0.05, 0.01, 0.01, 0.05], [0.0; 4])),
            _ => None,
        };
        Self {
            profile,
            rng,
            outer: OuterLoop::tracking(gravity),
            excitation,
            start,
            waypoint: [start[0], start[1], start[2]],
            heading: start[5],
            next_waypoint: 0.0,
        }
    }

    pub fn start(&self) -> [f64; 12] {
        self.start
    }

    /// The command at time t (from the segment start) for the measured state x.
    pub fn command(&mut self, t: f64, x: &[f64; 12]) -> [f64; 4] {
        match self.profile {
            Profile::Excite | Profile::ExciteHoldHeading => self.excite(t, x),
            Profile::Hover => {
                let r = Reference {
                    p: [self.start[0], self.start[1], self.start[2]],
                    ..Reference::default()
                };
                let u = self.outer.command(x, &r);
                let e = self.excitation.as_mut().map_or([0.0; 4], |e| e.at(t, &mut self.rng));
                [u[0] + e[0], u[1] + e[1], u[2] + e[2], u[3] + e[3]]
            }
            p => {
                let r = p.trajectory(t).unwrap_or_default();
                self.outer.command(x, &r)
            }
        }
    }

    fn excite(&mut self, t: f64, x: &[f64; 12]) -> [f64; 4] {
        if t >= self.next_waypoint {
            let low = self.rng.uniform() < 1.0 / 4.0;
            self.waypoint = [
                self.rng.range(-4.0, 4.0),
                self.rng.range(-4.0, 4.0),
                if low {
                    self.rng.range(0.1, 0.4)
                } else {
                    self.rng.range(1.5, 10.0)
                },
            ];
            let heading = self.rng.range(-std::f64::consts::PI, std::f64::consts::PI);
            if self.profile == Profile::Excite {
                self.heading = heading;
            }
            self.next_waypoint = t + self.rng.range(4.0, 8.0);
        }
        let e = match &mut self.excitation {
            Some(e) => e.at(t, &mut self.rng),
            None => [0.0; 4],
        };
        // Weak position keeping: a saturated velocity reference, a velocity loop.
        let mut v_ref = [0.5 * (self.waypoint[0] - x[0]), 0.5 * (self.waypoint[1] - x[1])];
        let speed = (v_ref[0] * v_ref[0] + v_ref[1] * v_ref[1]).sqrt();
        if speed > EXCITE_MAX_SPEED_REF {
            v_ref = [
                v_ref[0] * EXCITE_MAX_SPEED_REF / speed,
                v_ref[1] * EXCITE_MAX_SPEED_REF / speed,
            ];
        }
        let a = [1.0 * (v_ref[0] - x[6]), 1.0 * (v_ref[1] - x[7])];
        let [roll, pitch] = self.outer.tilt_for(a, x[5]);
        // Near the ground the vertical excitation fades, and below 0.1 m the pilot climbs.
        let z = x[2];
        let fade = ((z - 0.1) / 1.5).clamp(0.15, 1.0);
        let mut vz = (0.8 * (self.waypoint[2] - z)).clamp(-1.5, 1.5) + fade * e[0];
        if z < 0.1 {
            vz = vz.max(0.5);
        }
        let yaw_rate = 0.3 * wrap_angle(self.heading - x[5]) + e[3];
        // Tilt √(roll² + pitch²) at most EXCITE_MAX_TILT.
        let (roll, pitch) = (roll + e[1], pitch + e[2]);
        let tilt = (roll * roll + pitch * pitch).sqrt();
        let k = if tilt > EXCITE_MAX_TILT {
            EXCITE_MAX_TILT / tilt
        } else {
            1.0
        };
        [vz, k * roll, k * pitch, yaw_rate]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profile_lists_and_names() {
        assert_eq!(
            Profile::parse_list("excite, circle").unwrap(),
            vec![Profile::Excite, Profile::Circle]
        );
        let e = Profile::parse_list("excite,loop").unwrap_err();
        assert!(e.to_string().contains("unknown profile `loop`"), "{e}");
        assert!(Profile::parse_list("").is_err());
    }

    #[test]
    fn trajectory_derivatives_match_finite_differences() {
        for p in [Profile::Sinusoid, Profile::Circle, Profile::Spiral] {
            for t in [0.0, 1.3, 7.7] {
                let h = 1e-5;
                let (a, b, c) = (
                    p.trajectory(t - h).unwrap(),
                    p.trajectory(t).unwrap(),
                    p.trajectory(t + h).unwrap(),
                );
                for i in 0..3 {
                    assert!(((c.p[i] - a.p[i]) / (2.0 * h) - b.v[i]).abs() < 1e-6, "{p} v{i}");
                    assert!(((c.v[i] - a.v[i]) / (2.0 * h) - b.a[i]).abs() < 1e-6, "{p} a{i}");
                }
            }
        }
        // The paper's formulas at t = 0.
        assert_eq!(Profile::Circle.trajectory(0.0).unwrap().p, [5.0, 0.0, 6.0]);
        assert_eq!(Profile::Sinusoid.trajectory(0.0).unwrap().p, [3.0, 0.0, 6.0]);
        assert_eq!(Profile::Spiral.trajectory(0.0).unwrap().p, [1.0, 0.0, 5.0]);
    }
}
