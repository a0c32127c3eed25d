//! [`Plant`]: the vehicle behind its autopilot with every effect of a plant file, advanced one
//! sample at a time with the command held, RK4 at the fine rate inside.

use super::autopilot::Autopilot;
use super::effects::{Aero, AeroForce, Battery, DelayLine, GroundEffectModel, Measurement};
use super::plant_file::PlantFile;
use super::rigid_body::{
    body_rates_from_euler_rates, euler_rates_from_body_rates, euler_zyx, quat_from_euler, quat_to_matrix, rk4,
    BodyState, Inputs, V3,
};
use super::wind::WindField;

/// Wrap an angle to (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.sin().atan2(a.cos());
    if w <= -std::f64::consts::PI {
        std::f64::consts::PI
    } else {
        w
    }
}

/// Counters over the substeps since the plant was created or [`Plant::reset_stats`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantStats {
    pub substeps: u64,
    /// Substeps whose thrust command was clamped to 0 or to `max_thrust`.
    pub thrust_saturated: u64,
    /// Largest ground-effect thrust ratio met (1 without the effect).
    pub max_ground_ratio: f64,
    /// Substeps that ended below the ground and were put back on it.
    pub ground_contacts: u64,
}

/// The simulated vehicle. States are in the log's order
/// `[x y z roll pitch yaw vx vy vz roll_rate pitch_rate yaw_rate]` (inertial ENU position and
/// velocity, ZYX Euler angles, Euler-angle rates); yaw is continuous (not wrapped).
#[derive(Clone, Debug)]
pub struct Plant {
    autopilot: Autopilot,
    aero: Aero,
    battery: Battery,
    ground: Option<GroundEffectModel>,
    wind: Option<WindField>,
    delay: DelayLine,
    measurement: Measurement,
    motor_tau: Option<f64>,
    true_mass: f64,
    inertia: V3,
    gravity: f64,
    dt: f64,
    substeps: usize,
    state: BodyState,
    psi_sp: f64,
    yaw: f64,
    /// time = origin + steps · dt (no accumulated rounding).
    origin: f64,
    steps: u64,
    measured: [f64; 12],
    measured_voltage: f64,
    held: bool,
    command: [f64; 4],
    stats: PlantStats,
}

impl Plant {
    /// A plant at rest on the ground at the origin, t = 0. `file` should be validated
    /// ([`PlantFile::parse`] does); an invalid file gives meaningless numbers but no panic.
    pub fn new(file: &PlantFile, seed: u64) -> Plant {
        let e = &file.effects;
        let rate = if file.integration.rate_hz > 0.0 {
            file.integration.rate_hz
        } else {
            30.0
        };
        let mut plant = Plant {
            autopilot: Autopilot::new(file),
            aero: Aero::new(e, file.vehicle.mass),
            battery: Battery::new(file),
            ground: GroundEffectModel::new(file),
            wind: e.wind.as_ref().map(|w| WindField::new(w, seed)),
            delay: DelayLine::new(e.latency.as_ref().map(|l| l.delays()).unwrap_or([0.0; 4])),
            measurement: Measurement::new(file, seed),
            motor_tau: e.motor_lag.as_ref().map(|m| m.time_constant),
            true_mass: file.vehicle.mass + e.payload.as_ref().map_or(0.0, |p| p.mass),
            inertia: file.vehicle.inertia,
            gravity: file.vehicle.gravity,
            dt: 1.0 / rate,
            substeps: file.integration.substeps.max(1),
            state: BodyState {
                p: [0.0; 3],
                v: [0.0; 3],
                q: [1.0, 0.0, 0.0, 0.0],
                w: [0.0; 3],
                thrust: 0.0,
                torque: [0.0; 3],
            },
            psi_sp: 0.0,
            yaw: 0.0,
            origin: 0.0,
            steps: 0,
            measured: [0.0; 12],
            measured_voltage: 0.0,
            held: false,
            command: [0.0; 4],
            stats: PlantStats {
                max_ground_ratio: 1.0,
                ..PlantStats::default()
            },
        };
        plant.reset(&[0.0; 12]);
        plant
    }

    /// Place the vehicle at `x0` (true state, log order, rates = Euler rates), the yaw set-point
    /// at its yaw, the actuators at the autopilot's output for the hover command, and forget the
    /// pending (delayed) commands and the previous measurement. Time and battery go on.
    pub fn reset(&mut self, x0: &[f64; 12]) {
        let x: Vec<f64> = x0.iter().map(|v| if v.is_finite() { *v } else { 0.0 }).collect();
        self.state.p = [x[0], x[1], x[2]];
        self.state.q = quat_from_euler(x[3], x[4], x[5]);
        self.state.v = [x[6], x[7], x[8]];
        self.state.w = body_rates_from_euler_rates(x[3], x[4], [x[9], x[10], x[11]]);
        self.psi_sp = x[5];
        self.yaw = x[5];
        let (t, m) = self.autopilot.commands(&self.state, &[0.0; 4], self.psi_sp);
        self.state.thrust = t;
        self.state.torque = m;
        self.command = [0.0; 4];
        self.delay.clear();
        self.measurement.reset();
        self.measure();
    }

    /// Let `seconds` pass without flying (between segments): the clock and the battery go on,
    /// pending commands are dropped. Follow it with [`Plant::reset`].
    pub fn skip(&mut self, seconds: f64) {
        if seconds.is_finite() && seconds > 0.0 {
            self.origin = self.time() + seconds;
            self.steps = 0;
            self.delay.clear();
        }
    }

    /// Advance one sample period with the command `u` = [u_vz, u_roll, u_pitch, u_yaw_rate]
    /// held (clamped to the input limits, then delayed by the latency effect).
    pub fn step(&mut self, u: &[f64; 4]) {
        let u = self.autopilot.clamp(u);
        self.command = u;
        let t0 = self.time();
        self.delay.push(t0, u);
        let h = self.dt / self.substeps as f64;
        for j in 0..self.substeps {
            let s = t0 + j as f64 * h;
            let ud = self.delay.at(s);
            let (thrust, torque) = self.autopilot.commands(&self.state, &ud, self.psi_sp);
            if thrust <= 0.0 || thrust >= self.autopilot.max_thrust {
                self.stats.thrust_saturated += 1;
            }
            let ground = self.ground.as_ref().map_or(1.0, |g| g.ratio(self.state.p[2]));
            self.stats.max_ground_ratio = self.stats.max_ground_ratio.max(ground);
            let battery = self.battery.factor(s);
            let inputs = Inputs {
                thrust_cmd: thrust,
                torque_cmd: torque,
                motor_tau: self.motor_tau,
                thrust_factor: battery * ground,
                torque_factor: battery,
                mass: self.true_mass,
                inertia: self.inertia,
                gravity: self.gravity,
            };
            let wind = self.wind.as_ref().map_or([0.0; 3], |w| w.velocity());
            let force = AeroForce { aero: &self.aero, wind };
            self.state = rk4(&self.state, h, &inputs, &force);
            if let Some(w) = &mut self.wind {
                w.advance(h, self.state.v);
            }
            self.psi_sp += ud[3] * h;
            if self.state.p[2] < 0.0 {
                self.state.p[2] = 0.0;
                self.state.v[2] = self.state.v[2].max(0.0);
                self.stats.ground_contacts += 1;
            }
            self.stats.substeps += 1;
        }
        self.steps += 1;
        let yaw = euler_zyx(&quat_to_matrix(self.state.q))[2];
        self.yaw += wrap_angle(yaw - self.yaw);
        self.measure();
    }

    fn measure(&mut self) {
        let x = self.true_state();
        let (y, v, held) = self.measurement.sample(&x, self.true_battery_voltage());
        self.measured = y;
        self.measured_voltage = v;
        self.held = held;
    }

    /// What the log and a controller see: the true state with sensor noise and sample-and-hold.
    pub fn measured(&self) -> [f64; 12] {
        self.measured
    }

    /// Whether the current measurement repeats the previous one (sample-and-hold).
    pub fn measurement_held(&self) -> bool {
        self.held
    }

    /// The true state (log order, Euler rates, continuous yaw).
    pub fn true_state(&self) -> [f64; 12] {
        let s = &self.state;
        let e = euler_zyx(&quat_to_matrix(s.q));
        let rates = euler_rates_from_body_rates(e[0], e[1], s.w);
        [
            s.p[0], s.p[1], s.p[2], e[0], e[1], self.yaw, s.v[0], s.v[1], s.v[2], rates[0], rates[1], rates[2],
        ]
    }

    /// The logged battery voltage (with the `volt` sensor noise), V.
    pub fn battery_voltage(&self) -> f64 {
        self.measured_voltage
    }

    /// The battery voltage V(t) without noise, V.
    pub fn true_battery_voltage(&self) -> f64 {
        self.battery.voltage(self.time())
    }

    /// Thrust per command relative to a full battery (1 without `battery_sag`).
    pub fn thrust_factor(&self) -> f64 {
        self.battery.factor(self.time())
    }

    /// The last command as the autopilot accepted it (clamped, before the delay).
    pub fn command(&self) -> [f64; 4] {
        self.command
    }

    /// The wind now (inertial, m/s; zero without the effect).
    pub fn wind(&self) -> [f64; 3] {
        self.wind.as_ref().map_or([0.0; 3], |w| w.velocity())
    }

    /// The total rotor thrust now (after motor lag, battery and ground effect), N.
    pub fn thrust(&self) -> f64 {
        let ground = self.ground.as_ref().map_or(1.0, |g| g.ratio(self.state.p[2]));
        self.state.thrust * self.battery.factor(self.time()) * ground
    }

    /// The true mass (vehicle + payload), kg.
    pub fn true_mass(&self) -> f64 {
        self.true_mass
    }

    /// Flight time, s.
    pub fn time(&self) -> f64 {
        self.origin + self.steps as f64 * self.dt
    }

    /// 1 / `integration.rate_hz`, s.
    pub fn sample_period(&self) -> f64 {
        self.dt
    }

    /// Counters since creation or the last [`Plant::reset_stats`].
    pub fn stats(&self) -> PlantStats {
        self.stats
    }

    pub fn reset_stats(&mut self) {
        self.stats = PlantStats {
            max_ground_ratio: 1.0,
            ..PlantStats::default()
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::plant_file::tests_support::NOMINAL;

    fn nominal() -> PlantFile {
        PlantFile::parse(NOMINAL, "n.json").unwrap()
    }

    fn hover_at(z: f64) -> [f64; 12] {
        let mut x = [0.0; 12];
        x[2] = z;
        x
    }

    #[test]
    fn hover_holds_position() {
        let mut p = Plant::new(&nominal(), 1);
        p.reset(&hover_at(5.0));
        for _ in 0..300 {
            p.step(&[0.0; 4]);
        }
        let x = p.true_state();
        assert!(
            x.iter().enumerate().all(|(i, v)| (v - hover_at(5.0)[i]).abs() < 1e-9),
            "{x:?}"
        );
        assert!((p.time() - 10.0).abs() < 1e-12);
        assert_eq!(p.measured(), x);
    }

    #[test]
    fn non_finite_commands_and_states_are_hover_and_zero() {
        let mut p = Plant::new(&nominal(), 1);
        let mut x0 = hover_at(5.0);
        x0[0] = f64::NAN;
        x0[6] = f64::INFINITY;
        p.reset(&x0);
        assert_eq!(p.true_state(), hover_at(5.0));
        p.step(&[f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::NAN]);
        assert_eq!(p.command(), [0.0; 4]);
        assert!(p.true_state().iter().all(|v| v.is_finite()));
        assert!((p.true_state()[2] - 5.0).abs() < 1e-12);
    }

    #[test]
    fn vz_step_has_time_constant_one_over_k_vz() {
        let mut p = Plant::new(&nominal(), 1);
        p.reset(&hover_at(5.0));
        // One time constant 1/k_vz = 0.4 s = 12 samples: vz = 1 − e⁻¹ of the command in
        // continuous time. The autopilot runs at the RK4 rate (thrust held over a substep h), so
        // exactly vz = 1 − (1 − h k_vz)^(7·12).
        for _ in 0..12 {
            p.step(&[1.0, 0.0, 0.0, 0.0]);
        }
        let vz = p.true_state()[8];
        let h = 1.0 / 210.0;
        assert!((vz - (1.0 - (1.0 - h * 2.5f64).powi(84))).abs() < 1e-9, "vz {vz}");
        assert!((vz - (1.0 - (-1.0f64).exp())).abs() < 3e-3, "vz {vz}");
        for _ in 0..90 {
            p.step(&[1.0, 0.0, 0.0, 0.0]);
        }
        assert!((p.true_state()[8] - 1.0).abs() < 1e-3);
    }

    #[test]
    fn attitude_step_reaches_the_command() {
        let mut p = Plant::new(&nominal(), 1);
        p.reset(&hover_at(5.0));
        for _ in 0..60 {
            p.step(&[0.0, 0.2, -0.1, 0.0]);
        }
        let x = p.true_state();
        assert!((x[3] - 0.2).abs() < 1e-4 && (x[4] + 0.1).abs() < 1e-4, "{x:?}");
        // Altitude held by the tilt compensation while the vehicle accelerates sideways.
        assert!(x[8].abs() < 1e-3, "vz {}", x[8]);
        assert!(
            x[6] < -1.0 && x[7] < -1.0,
            "tilted by roll > 0 (−y) and pitch < 0 (−x): {x:?}"
        );
        // Yaw rate follows the command.
        for _ in 0..90 {
            p.step(&[0.0, 0.0, 0.0, 0.5]);
        }
        assert!((p.true_state()[11] - 0.5).abs() < 5e-3, "{:?}", p.true_state());
    }
}
