#!/usr/bin/env python3
"""Logs -> model -> compiled MPC -> closed loop -> plot, all from Python (examples/python/README.md).

1. **Logs.** A simulated aircraft — the shipped M100 model, models/sindy_m100.json, with its 0.13 s
   u_vz latency, compiled by uavgen and stepped through its C ABI's ``discrete_dynamics`` — flies
   60 s of stepped excitation commands; the samples are written as a uavgen flight log
   (docs/log-format.md, ``uavgen.Log.from_numpy(...).save``) and read back with ``uavgen.read_log``.
2. **Model.** PySINDy fits the six dynamic rows (vx … yaw_rate) on the log with uavgen's state names
   (derivatives by finite differences); the kinematic rows x' = vx, … are exact. The fitted
   ``pysindy.SINDy`` becomes a uavgen ``Model`` with ``Model.from_pysindy`` — no export script.
   (``uavgen.identify(logs, method="sindy")`` is the other way in: docs/python.md.)
3. **MPC.** ``uavgen.compile(model, horizon=30)`` generates the crate with its C ABI, builds it with
   cargo (cached) and loads it; ``uavgen.compile.Controller`` runs the runtime's timeline
   (feedback, then prepare the next sample) exactly as ``uavgen track``'s harness does.
4. **Closed loop** on the simulated aircraft along the paper's circle, 20 s, and a matplotlib figure.

Run from the repository root (needs cargo, pysindy, matplotlib)::

    python examples/python/closed_loop.py --out out/python-example

It writes ``flight.csv``, ``model.json``, ``closed_loop.png`` and prints the tracking RMSE.
"""

import argparse
import warnings
from pathlib import Path

import numpy as np

import uavgen
from uavgen.compile import Controller, trajectory_state

REPO = Path(__file__).resolve().parents[2]
STATES = ["x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"]
INPUTS = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"]
DYNAMIC = STATES[6:]


class Aircraft:
    """The simulated aircraft: a compiled model's discrete dynamics with its input delays held."""

    def __init__(self, mpc, x0):
        self.mpc, self.x = mpc, np.array(x0, dtype=float)
        self.delays = mpc.input_delay_samples
        self.sent = [np.zeros(mpc.nu)] * (max(self.delays) + 1)

    def step(self, u):
        self.sent = [np.asarray(u, dtype=float)] + self.sent[:-1]
        acting = np.array([self.sent[d][i] for i, d in enumerate(self.delays)])
        self.x = self.mpc.discrete_dynamics(self.x, acting)
        return self.x


def fly_excitation(aircraft, seconds, rng):
    """Stepped random commands (held 0.5-1.5 s) around hover, as a logging flight would fly."""
    dt = aircraft.mpc.dt
    n = int(round(seconds / dt))
    lo = np.array([-1.0, -0.25, -0.25, -0.6])
    X, U = np.zeros((n, 12)), np.zeros((n, 4))
    u, hold = np.zeros(4), 0
    for k in range(n):
        if hold == 0:
            u, hold = rng.uniform(lo, -lo), int(rng.integers(15, 45))
            # Damp the velocities (a pilot keeping the aircraft near its start), stay within bounds.
            u[1] += 0.08 * aircraft.x[7]
            u[2] -= 0.08 * aircraft.x[6]
            u[0] -= 0.5 * (aircraft.x[2] - 5.0)
            u[3] -= 1.0 * aircraft.x[5]  # heading back to 0: the fit is local in yaw
            u = np.clip(u, 2 * lo, -2 * lo)
        hold -= 1
        X[k], U[k] = aircraft.x, u
        aircraft.step(u)
    return np.arange(n) * dt, X, U


def write_log(path, t, X, U, rate_hz):
    """The flight log CSV (docs/log-format.md), written and checked by uavgen's own log reader."""
    uavgen.Log.from_numpy(t, X, U, rate_hz=rate_hz, name="excitation flight").save(path, force=True)


def read_log(path):
    d = uavgen.read_log(path).to_numpy()
    return d["t"], d["x"], d["u"]


def fit_pysindy(t, X, U, delays):
    """PySINDy on the log: x = the six dynamic states, u = the attitude angles and the inputs as
    they acted (each delayed by its latency in samples), a linear library (1, every variable), the integral
    form of the targets (docs/sindy.md: each sample's mean slope against the library at the
    interval's midpoint, the input held over it)."""
    import pysindy as ps

    dt = t[1] - t[0]
    acting = np.array([[U[max(k - d, 0), i] for i, d in enumerate(delays)] for k in range(len(t))])
    mid = 0.5 * (X[:-1] + X[1:])
    targets = (X[1:, 6:] - X[:-1, 6:]) / dt
    u = np.column_stack([mid[:, 3:6], acting[:-1]])
    names = DYNAMIC + STATES[3:6] + INPUTS
    model = ps.SINDy(feature_library=ps.PolynomialLibrary(degree=1),
                     optimizer=ps.STLSQ(threshold=0.05, alpha=1e-6))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model.fit(mid[:, 6:], t=dt, x_dot=targets, u=u, feature_names=names)
    return model


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/python-example")
    ap.add_argument("--seconds", type=float, default=20.0, help="closed-loop flight time")
    ap.add_argument("--trajectory", default="circle", choices=["circle", "sinusoid", "spiral"])
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    # 1. The simulated aircraft and its log.
    truth = uavgen.Model.from_json((REPO / "models" / "sindy_m100.json").read_text(), "models/sindy_m100.json")
    sim = uavgen.compile(truth, horizon=30)  # we only use its discrete_dynamics: the simulator
    start = np.array([0.0, 0.0, 5.0] + [0.0] * 9)
    t, X, U = fly_excitation(Aircraft(sim, start), 60.0, np.random.default_rng(7))
    write_log(out / "flight.csv", t, X, U, 1.0 / sim.dt)
    t, X, U = read_log(out / "flight.csv")
    print(f"log: {len(t)} samples at {1 / (t[1] - t[0]):.0f} Hz -> {out / 'flight.csv'}")

    # 2. The model, fitted in PySINDy. The six dynamic rows come from PySINDy; the six kinematic
    # rows are exact. PySINDy's "x" holds the dynamic states, its "u" the angles and the inputs;
    # from_pysindy gives that 6-state model, widened here to the 12 states with the kinematic rows
    # (the terms keep their names: roll, pitch, yaw become states).
    fitted = fit_pysindy(t, X, U, sim.input_delay_samples)
    six = uavgen.Model.from_pysindy(fitted, name="python_example")
    import json

    doc = json.loads(six.to_json())
    doc["states"], doc["inputs"] = STATES, INPUTS
    doc["kinematic"] = [[a, b] for a, b in zip(STATES[:6], DYNAMIC)]
    # The aircraft's input delays (known here; uavgen.identify's delay scan finds them from logs).
    doc["corrections"] = {"latency": {n: d * sim.dt for n, d in zip(INPUTS, sim.input_delay_samples) if d}}
    model = uavgen.Model.from_json(json.dumps(doc), "python_example")
    (out / "model.json").write_text(model.to_json())
    print(f"model: {len(doc['coefficients'])} coefficients -> {out / 'model.json'}")

    # 3. The compiled MPC and the runtime's controller.
    mpc = uavgen.compile(model, horizon=30)
    print(mpc)
    ctl = Controller(mpc, args.trajectory)
    x0 = np.array([3.0, 3.0, 5.0] + [0.0] * 9)
    ctl.initialize(x0)
    ctl.start(0.0)

    # 4. Closed loop on the simulated aircraft.
    aircraft = Aircraft(sim, x0)
    n = int(round(args.seconds / mpc.dt))
    times, pos, ref, inputs, statuses = [], [], [], [], {}
    x = x0
    for k in range(n):
        u, status = ctl.step(x)
        statuses[status.name] = statuses.get(status.name, 0) + 1
        times.append(k * mpc.dt)
        pos.append(x[:3].copy())
        ref.append(trajectory_state(args.trajectory, k * mpc.dt, 12)[:3])
        inputs.append(u)
        x = aircraft.step(u)
    pos, ref, inputs = np.array(pos), np.array(ref), np.array(inputs)
    half = n // 2
    rmse = float(np.sqrt(np.mean(np.sum((pos[half:] - ref[half:]) ** 2, axis=1))))
    print(f"closed loop: {args.seconds:g} s of the {args.trajectory}, statuses {statuses}, "
          f"position RMSE over the second half {rmse:.3f} m")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    axes[0].plot(ref[:, 0], ref[:, 1], "k--", label="reference")
    axes[0].plot(pos[:, 0], pos[:, 1], label="flown")
    axes[0].set_xlabel("x (m)"), axes[0].set_ylabel("y (m)"), axes[0].axis("equal"), axes[0].legend()
    axes[0].set_title(f"{args.trajectory}: compiled MPC of the PySINDy model")
    for i, name in enumerate(INPUTS):
        axes[1].plot(times, inputs[:, i], label=name)
    axes[1].set_xlabel("t (s)"), axes[1].set_title("inputs"), axes[1].legend()
    fig.tight_layout()
    fig.savefig(out / "closed_loop.png", dpi=110)
    print(f"plot -> {out / 'closed_loop.png'}")


if __name__ == "__main__":
    main()
