#!/usr/bin/env python3
"""RotorPy's Crazyflie as an independent check of the aircraft bed (issue 27; docs/simulate.md).

No code of uavgen's flies here: the vehicle is RotorPy's own multirotor model (PyPI `rotorpy`, its
`crazyflie_params`: mass, inertia, rotor thrust and drag coefficients, 72 ms motor time constant, aero
on) under RotorPy's own `cmd_ctatt` attitude control (its kp_att 310, kd_att 57). In front of it, as the
shared RotorPy logs (../shared/flights/rotorpy_nominal_truth.json) were made:

  vertical:  thrust = m (g + k_vz (u_vz - vz)) / (cos roll cos pitch), k_vz 4 1/s, no integral;
  attitude:  R_des = Rz(psi_sp + (kd_att/kp_att) u_yaw_rate) Ry(u_pitch) Rx(u_roll),
             psi_sp = integral of u_yaw_rate;

and a pilot written here after uavgen's `excite` / `excite-hold-heading` profiles (docs/simulate.md:
multisines 0.05-2.5 Hz plus random steps on all four inputs, a weak loop to random waypoints, the
commanded tilt limited to 0.35 rad = 20 deg, u_vz to +-1 m/s; `hold` keeps the heading, u_yaw_rate then
carries only the weak heading loop). Commands at 100 Hz (held), RotorPy integrates 5 steps per sample
(its attitude loop at 500 Hz), states logged at 100 Hz with motion-capture-grade noise.

Writes, in uavgen's CSV (docs/log-format.md): train_excite.csv, train_hold.csv, test_excite.csv,
test_hold.csv and rotorpy_cf_truth.json (everything needed to know what was flown). Seeded: the same
arguments give the same bytes (numpy's PCG64; RotorPy's motor noise is 0 for the Crazyflie).

Usage: python3 scripts/rotorpy_crazyflie.py [--out tests/data/rotorpy_cf] [--train-s 15] [--test-s 8]
Needs `pip install rotorpy` (3.0.0 was used for the committed logs).
"""
import argparse
import json
import math
import os

import numpy as np

RATE_HZ = 100.0
SUBSTEPS = 5
K_VZ = 4.0
MAX_TILT = 0.35
MAX_VZ = 1.0
MAX_YAW_RATE = 3.49
MAX_SPEED_REF = 2.5
NOISE = {"pos": 0.0005, "vel": 0.01, "att": 0.002, "rate": 0.02}
# (name, profile, seed): the seeds of the committed logs.
FLIGHTS = [("train_excite", "excite", 4001), ("train_hold", "hold", 4002),
           ("test_excite", "excite", 4003), ("test_hold", "hold", 4004)]
COLUMNS = "t,x,y,z,roll,pitch,yaw,vx,vy,vz,roll_rate,pitch_rate,yaw_rate,u_vz,u_roll,u_pitch,u_yaw_rate"


def rot_zyx(roll, pitch, yaw):
    cr, sr, cp, sp, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def euler_zyx(r):
    pitch = -math.asin(max(-1.0, min(1.0, r[2, 0])))
    roll = math.atan2(r[2, 1], r[2, 2])
    yaw = math.atan2(r[1, 0], r[0, 0])
    return roll, pitch, yaw


def euler_rates(roll, pitch, w):
    """Body rates -> time derivatives of the ZYX Euler angles."""
    sr, cr, tp, cp = math.sin(roll), math.cos(roll), math.tan(pitch), math.cos(pitch)
    return (w[0] + sr * tp * w[1] + cr * tp * w[2], cr * w[1] - sr * w[2], (sr * w[1] + cr * w[2]) / cp)


def wrap(a):
    return math.atan2(math.sin(a), math.cos(a))


class Pilot:
    """uavgen's `excite` pilot (generator/src/sim/profiles.rs), re-written; `hold` = excite-hold-heading."""

    def __init__(self, rng, hold, heading):
        self.rng, self.hold = rng, hold
        rms = [0.4, 0.06, 0.06, 0.0 if hold else 0.2]
        step = [0.7, 0.1, 0.1, 0.0 if hold else 0.4]
        n = 10
        self.sines = []
        for r in rms:
            amp = r * math.sqrt(2.0 / n)
            self.sines.append([(amp, 2 * math.pi * 0.05 * (2.5 / 0.05) ** (k / (n - 1)), rng.uniform(0, 2 * math.pi))
                               for k in range(n)])
        self.step_amp = step
        self.step_val = [0.0] * 4
        self.step_until = [0.0] * 4
        self.heading = heading
        self.waypoint = [0.0, 0.0, 1.5]
        self.next_waypoint = 0.0

    def command(self, t, x, g=9.81):
        rng = self.rng
        if t >= self.next_waypoint:
            low = rng.uniform() < 0.25
            self.waypoint = [rng.uniform(-4, 4), rng.uniform(-4, 4), rng.uniform(0.1, 0.4) if low else rng.uniform(1.5, 10)]
            h = rng.uniform(-math.pi, math.pi)
            if not self.hold:
                self.heading = h
            self.next_waypoint = t + rng.uniform(4, 8)
        e = []
        for i in range(4):
            if t >= self.step_until[i]:
                self.step_val[i] = rng.uniform(-self.step_amp[i], self.step_amp[i])
                self.step_until[i] = t + rng.uniform(0.5, 3.0)
            e.append(sum(a * math.sin(w * t + p) for a, w, p in self.sines[i]) + self.step_val[i])
        v_ref = [0.5 * (self.waypoint[0] - x[0]), 0.5 * (self.waypoint[1] - x[1])]
        s = math.hypot(*v_ref)
        if s > MAX_SPEED_REF:
            v_ref = [v * MAX_SPEED_REF / s for v in v_ref]
        ax, ay = v_ref[0] - x[6], v_ref[1] - x[7]
        c, sn = math.cos(x[5]), math.sin(x[5])
        pitch = (c * ax + sn * ay) / g
        roll = (sn * ax - c * ay) / g
        z = x[2]
        fade = min(1.0, max(0.15, (z - 0.1) / 1.5))
        vz = min(1.5, max(-1.5, 0.8 * (self.waypoint[2] - z))) + fade * e[0]
        if z < 0.1:
            vz = max(vz, 0.5)
        yaw_rate = 0.3 * wrap(self.heading - x[5]) + e[3]
        roll, pitch = roll + e[1], pitch + e[2]
        tilt = math.hypot(roll, pitch)
        k = MAX_TILT / tilt if tilt > MAX_TILT else 1.0
        return [min(MAX_VZ, max(-MAX_VZ, vz)), k * roll, k * pitch, min(MAX_YAW_RATE, max(-MAX_YAW_RATE, yaw_rate))]


def fly(params, profile, seed, duration):
    from rotorpy.vehicles.multirotor import Multirotor
    from scipy.spatial.transform import Rotation

    rng = np.random.Generator(np.random.PCG64(seed))
    heading = rng.uniform(-math.pi, math.pi)
    m, g = params["mass"], 9.81
    hover = math.sqrt(m * g / (4 * params["k_eta"]))
    state = {"x": np.array([0.0, 0.0, 1.5]), "v": np.zeros(3),
             "q": Rotation.from_matrix(rot_zyx(0, 0, heading)).as_quat(), "w": np.zeros(3),
             "wind": np.zeros(3), "rotor_speeds": np.full(4, hover)}
    quad = Multirotor(params, initial_state=state, control_abstraction="cmd_ctatt", aero=True, enable_ground=True)
    pilot = Pilot(rng, profile == "hold", heading)
    dt = 1.0 / RATE_HZ
    psi_sp = heading
    lead = params["kd_att"] / params["kp_att"]
    rows = []
    stats = {"max_tilt": 0.0, "min_z": 1e9, "max_z": -1e9, "max_abs_xy": 0.0, "max_speed": 0.0, "rotor_sat": 0}
    for k in range(int(round(duration * RATE_HZ))):
        t = k * dt
        r = Rotation.from_quat(state["q"]).as_matrix()
        roll, pitch, yaw = euler_zyx(r)
        er = euler_rates(roll, pitch, state["w"])
        true = [*state["x"], roll, pitch, yaw, *state["v"], *er]
        noisy = list(true)
        for i, key in [(0, "pos"), (1, "pos"), (2, "pos"), (3, "att"), (4, "att"), (5, "att"), (6, "vel"), (7, "vel"),
                       (8, "vel"), (9, "rate"), (10, "rate"), (11, "rate")]:
            noisy[i] += rng.normal(0.0, NOISE[key])
        noisy[5] = wrap(noisy[5])
        u = pilot.command(t, noisy, g)
        rows.append((t, noisy, u))
        stats["max_tilt"] = max(stats["max_tilt"], math.acos(max(-1.0, min(1.0, r[2, 2]))))
        stats["min_z"], stats["max_z"] = min(stats["min_z"], true[2]), max(stats["max_z"], true[2])
        stats["max_abs_xy"] = max(stats["max_abs_xy"], abs(true[0]), abs(true[1]))
        stats["max_speed"] = max(stats["max_speed"], float(np.linalg.norm(state["v"])))
        # The autopilot in front of RotorPy's cmd_ctatt (it sees the true state).
        for _ in range(SUBSTEPS):
            r = Rotation.from_quat(state["q"]).as_matrix()
            thrust = m * (g + K_VZ * (u[0] - state["v"][2])) / max(0.3, r[2, 2])
            r_des = rot_zyx(u[1], u[2], psi_sp + lead * u[3])
            control = {"cmd_thrust": thrust, "cmd_q": Rotation.from_matrix(r_des).as_quat()}
            cmd = quad.get_cmd_motor_speeds(state, control)
            stats["rotor_sat"] += int(np.any(cmd > params["rotor_speed_max"]) or np.any(cmd < params["rotor_speed_min"]))
            state = quad.step(state, control, dt / SUBSTEPS)
            psi_sp = wrap(psi_sp + u[3] * dt / SUBSTEPS)
    stats["rotor_saturated_fraction"] = stats.pop("rotor_sat") / (len(rows) * SUBSTEPS)
    return rows, stats


def write_csv(path, name, profile, seed, duration, rows):
    with open(path, "w", newline="\n") as f:
        f.write("# format: uavgen flight log v1\n")
        f.write("# source: RotorPy simulation (scripts/rotorpy_crazyflie.py)\n")
        f.write("# vehicle: RotorPy crazyflie_params (cmd_ctatt)\n")
        f.write(f"# rate_hz: {RATE_HZ:g}\n# profile: {profile}\n# seed: {seed}\n# duration_s: {duration:g}\n")
        f.write(COLUMNS + "\n")
        for t, x, u in rows:
            vals = [f"{t:.2f}"] + [f"{v:.4f}" for v in x[:6]] + [f"{v:.3f}" for v in x[6:]] + [f"{v:.4f}" for v in u]
            f.write(",".join(v.replace("-0.0000", "0.0000").replace("-0.000", "0.000") for v in vals) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", default="tests/data/rotorpy_cf")
    ap.add_argument("--train-s", type=float, default=15.0)
    ap.add_argument("--test-s", type=float, default=8.0)
    args = ap.parse_args()
    import rotorpy
    from rotorpy.vehicles.crazyflie_params import quad_params

    params = dict(quad_params)
    os.makedirs(args.out, exist_ok=True)
    files = {}
    for name, profile, seed in FLIGHTS:
        duration = args.train_s if name.startswith("train") else args.test_s
        rows, stats = fly(params, profile, seed, duration)
        write_csv(os.path.join(args.out, name + ".csv"), name, profile, seed, duration, rows)
        files[name] = {"csv": name + ".csv", "profile": "excite" if profile == "excite" else "excite-hold-heading",
                       "seed": seed, "duration_s": duration, "rows": len(rows),
                       **{k: round(v, 4) for k, v in stats.items()}}
        print(f"{name}: {len(rows)} rows, {json.dumps(files[name])}")
    truth = {
        "engine": f"rotorpy {getattr(rotorpy, '__version__', '3.0.0')} (PyPI), Multirotor(crazyflie_params, "
                  "control_abstraction='cmd_ctatt', aero=True, enable_ground=True)",
        "command": f"python3 scripts/rotorpy_crazyflie.py --out {args.out} --train-s {args.train_s:g} "
                   f"--test-s {args.test_s:g}",
        "rate_hz": RATE_HZ,
        "sim_step_s": 1.0 / (RATE_HZ * SUBSTEPS),
        "vehicle": {
            "name": "RotorPy crazyflie_params",
            "mass_kg_true": params["mass"],
            "inertia_diag_kg_m2_true": [params["Ixx"], params["Iyy"], params["Izz"]],
            "k_eta_N_per_rad2s2": params["k_eta"], "k_m_Nm_per_rad2s2": params["k_m"],
            "rotor_drag_k_d": params["k_d"], "induced_inflow_k_z": params["k_z"],
            "rotor_speed_max_rad_s": params["rotor_speed_max"], "tau_m_s": params["tau_m"],
            "max_thrust_to_weight": 4 * params["k_eta"] * params["rotor_speed_max"] ** 2 / (params["mass"] * 9.81),
            "aero_enabled": True,
        },
        "autopilot": {
            "vertical": "thrust = m*(g + k_vz*(u_vz - vz))/(cos roll cos pitch), no integral",
            "k_vz_1_per_s": K_VZ,
            "attitude": "RotorPy cmd_ctatt: M = I(-kp*e_R - kd*w) + w x I w, R_des = Rz(psi_sp + (kd/kp) u_yaw_rate) "
                        "Ry(u_pitch) Rx(u_roll), psi_sp = integral of u_yaw_rate",
            "kp_att": [params["kp_att"]] * 3, "kd_att": [params["kd_att"]] * 3,
            "input_limits": [MAX_VZ, MAX_TILT, MAX_TILT, MAX_YAW_RATE],
        },
        "noise_sigma": NOISE,
        "noise_model": "white Gaussian on the logged states; the pilot sees the noisy values, the autopilot the true state",
        "files": files,
    }
    with open(os.path.join(args.out, "rotorpy_cf_truth.json"), "w", newline="\n") as f:
        json.dump(truth, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()
