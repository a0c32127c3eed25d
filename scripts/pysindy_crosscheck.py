#!/usr/bin/env python3
"""Write the PySINDy cross-check fixture for uavgen's SINDy optimisers.

    python3 scripts/pysindy_crosscheck.py [--out tests/fixtures/sindy_crosscheck.json]

Needs ``pip install pysindy numpy scipy`` (the committed fixture was written with PySINDy 2.1.0,
numpy 2.x, scikit-learn 1.x).

Data: 600 deterministic samples (numpy ``default_rng(20240604)``) of uavgen's 16 variables, drawn
independently and uniformly (angles over wide ranges, so sin/cos columns are far from collinear),
rounded to 10 significant digits; and derivatives of a toy vehicle written in terms of the paper's
library, plus Gaussian noise (sigma 0.02), rounded likewise:

    x' = vx, y' = vy, z' = vz, roll' = roll_rate, pitch' = pitch_rate, yaw' = yaw_rate
    vx' = -0.4 vx + 9.81 pitch cos(yaw) + 9.81 roll sin(yaw)
    vy' = -0.4 vy + 9.81 pitch sin(yaw) - 9.81 roll cos(yaw)
    vz' = 2 u_vz - 2 vz - 0.3 vz^2 + 0.5
    roll_rate'  = 16 u_roll - 16 roll - 6 roll_rate
    pitch_rate' = 16 u_pitch - 16 pitch - 6 pitch_rate + 0.5 pitch_rate u_vz
    yaw_rate'   = 3 u_yaw_rate - 3 yaw_rate + 0.08 yaw_rate^2

Library: the term strings of uavgen's ``paper`` (155 terms, all 12 targets) and ``physics``
(72 terms, the 6 dynamic targets) libraries, listed in the fixture and evaluated here by a small
evaluator of the term grammar (``a*b``, ``a^k``, ``sin(v)``, ``cos(v)``). Θ is passed to the
optimisers directly, ``optimizer.fit(Theta, dX)``, so PySINDy and uavgen regress on the same
columns by construction; the fixture records the column norms of Θ so the Rust test can check its
own evaluation of the terms.

Cases: STLSQ (raw and normalised columns), SR3 with L0 and L1 (normalised; one of them converged,
one stopped by max_iter), written as PySINDy's ``coef_`` (targets x features) plus its iteration
count. The Rust test (generator/tests/sindy.rs) reruns uavgen's optimisers with the same settings
and asserts the same support and coefficients within 1e-6 relative.
"""

import argparse
import json
import re
import warnings

import numpy as np
import pysindy as ps

STATES = ["x", "y", "z", "roll", "pitch", "yaw",
          "vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"]
INPUTS = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"]
VARS = STATES + INPUTS
ANGLES = ["roll", "pitch", "yaw"]
DYNAMIC = ["vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"]
PHYSICS_STATES = ["roll", "pitch", "vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"]
N = 600
SEED = 20240604
NOISE = 0.02


def paper_library():
    t = ["1"] + STATES + INPUTS + [f"{s}^2" for s in STATES]
    t += [f"{s}*{u}" for s in STATES for u in INPUTS]
    t += [f"sin({a})" for a in ANGLES] + [f"cos({a})" for a in ANGLES]
    t += [f"{s}*{f}({a})" for f in ["sin", "cos"] for s in STATES for a in ANGLES]
    return t


def physics_library():
    t = ["1"] + PHYSICS_STATES + INPUTS + [f"{s}^2" for s in PHYSICS_STATES]
    t += [f"{s}*{u}" for s in PHYSICS_STATES for u in INPUTS]
    t += ["cos(roll)", "cos(pitch)", "cos(roll)*cos(pitch)"]
    t += ["sin(yaw)", "cos(yaw)"]
    for a in ["u_roll", "u_pitch", "sin(roll)", "sin(pitch)"]:
        t += [f"{a}*sin(yaw)", f"{a}*cos(yaw)"]
    return t


FACTOR = re.compile(r"^(?:(sin|cos)\((\w+)\)|(\w+))(?:\^(\d+))?$")


def evaluate(term, cols):
    """One library column from the term string (the model grammar's `*`-separated form)."""
    if term == "1":
        return np.ones(N)
    out = np.ones(N)
    for f in term.split("*"):
        m = FACTOR.match(f)
        if not m:
            raise ValueError(f"bad factor {f!r} in {term!r}")
        fn, arg, var, power = m.groups()
        base = {"sin": np.sin, "cos": np.cos}[fn](cols[arg]) if fn else cols[var]
        out = out * base ** int(power or 1)
    return out


def r10(a):
    """Round to 10 significant digits (the fixture then holds exactly the values fitted)."""
    return np.array([float(f"{v:.10g}") for v in np.ravel(a)]).reshape(np.shape(a))


def make_data():
    rng = np.random.default_rng(SEED)
    lo_hi = {
        "x": 3, "y": 3, "z": 3, "roll": 1.4, "pitch": 1.4, "yaw": np.pi,
        "vx": 2, "vy": 2, "vz": 1, "roll_rate": 1.5, "pitch_rate": 1.5, "yaw_rate": 1.5,
        "u_vz": 1, "u_roll": 0.6, "u_pitch": 0.6, "u_yaw_rate": 1,
    }
    cols = {v: r10(rng.uniform(-lo_hi[v], lo_hi[v], N)) for v in VARS}
    c = cols
    d = {
        "x": c["vx"], "y": c["vy"], "z": c["vz"],
        "roll": c["roll_rate"], "pitch": c["pitch_rate"], "yaw": c["yaw_rate"],
        "vx": -0.4 * c["vx"] + 9.81 * c["pitch"] * np.cos(c["yaw"]) + 9.81 * c["roll"] * np.sin(c["yaw"]),
        "vy": -0.4 * c["vy"] + 9.81 * c["pitch"] * np.sin(c["yaw"]) - 9.81 * c["roll"] * np.cos(c["yaw"]),
        "vz": 2 * c["u_vz"] - 2 * c["vz"] - 0.3 * c["vz"] ** 2 + 0.5,
        "roll_rate": 16 * c["u_roll"] - 16 * c["roll"] - 6 * c["roll_rate"],
        "pitch_rate": 16 * c["u_pitch"] - 16 * c["pitch"] - 6 * c["pitch_rate"]
        + 0.5 * c["pitch_rate"] * c["u_vz"],
        "yaw_rate": 3 * c["u_yaw_rate"] - 3 * c["yaw_rate"] + 0.08 * c["yaw_rate"] ** 2,
    }
    dx = {s: r10(d[s] + NOISE * rng.standard_normal(N)) for s in STATES}
    return cols, dx


CASES = [
    # (name, library, settings); settings use PySINDy's parameter names.
    ("stlsq_raw", "paper", dict(optimizer="STLSQ", threshold=0.05, alpha=1e-3, max_iter=20,
                                normalize_columns=False, unbias=True)),
    ("stlsq_normalized", "paper", dict(optimizer="STLSQ", threshold=0.5, alpha=1e-3, max_iter=20,
                                       normalize_columns=True, unbias=True)),
    ("stlsq_biased", "physics", dict(optimizer="STLSQ", threshold=0.5, alpha=0.05, max_iter=20,
                                     normalize_columns=True, unbias=False)),
    ("sr3_l0", "paper", dict(optimizer="SR3", regularizer="L0", reg_weight_lam=0.125,
                             relax_coeff_nu=1.0, max_iter=1000, tol=1e-10,
                             normalize_columns=True, unbias=False)),
    ("sr3_l1", "paper", dict(optimizer="SR3", regularizer="L1", reg_weight_lam=0.5,
                             relax_coeff_nu=1.0, max_iter=1000, tol=1e-10,
                             normalize_columns=True, unbias=False)),
    ("sr3_l0_defaults", "physics", dict(optimizer="SR3", regularizer="L0", reg_weight_lam=0.125,
                                        relax_coeff_nu=1.0, max_iter=30, tol=1e-5,
                                        normalize_columns=True, unbias=False)),
    ("sr3_l1_unbiased", "physics", dict(optimizer="SR3", regularizer="L1", reg_weight_lam=0.5,
                                        relax_coeff_nu=0.5, max_iter=1000, tol=1e-10,
                                        normalize_columns=True, unbias=True)),
]


def fit_case(theta, y, s):
    kw = {k: v for k, v in s.items() if k != "optimizer"}
    opt = ps.STLSQ(**kw) if s["optimizer"] == "STLSQ" else ps.SR3(**kw)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        opt.fit(theta, y)
    msgs = [str(w.message) for w in caught]
    converged = not any("did not converge" in m for m in msgs)
    return opt, converged


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default="tests/fixtures/sindy_crosscheck.json")
    args = ap.parse_args()
    cols, dx = make_data()
    libs = {"paper": (paper_library(), STATES), "physics": (physics_library(), DYNAMIC)}
    cases = []
    for name, lib, settings in CASES:
        terms, targets = libs[lib]
        theta = np.column_stack([evaluate(t, cols) for t in terms])
        y = np.column_stack([dx[s] for s in targets])
        opt, converged = fit_case(theta, y, settings)
        coef = np.asarray(opt.coef_)
        cases.append({
            "name": name,
            "library": lib,
            "targets": targets,
            "settings": settings,
            "iterations": int(opt.iters) if settings["optimizer"] == "SR3" else len(opt.history_) - 1,
            "converged": converged,
            "nonzeros": int(np.count_nonzero(coef)),
            "coef": coef.tolist(),
        })
        print(f"{name}: {np.count_nonzero(coef)} non-zeros, iterations {cases[-1]['iterations']}, "
              f"converged {converged}")
    fixture = {
        "generator": "scripts/pysindy_crosscheck.py",
        "pysindy_version": ps.__version__,
        "numpy_version": np.__version__,
        "seed": SEED,
        "samples": N,
        "noise_sigma": NOISE,
        "states": STATES,
        "inputs": INPUTS,
        "libraries": {k: v[0] for k, v in libs.items()},
        "theta_column_norms": {
            k: [float(np.linalg.norm(evaluate(t, cols))) for t in v[0]] for k, v in libs.items()
        },
        "x": np.column_stack([cols[s] for s in STATES]).tolist(),
        "u": np.column_stack([cols[s] for s in INPUTS]).tolist(),
        "dx": np.column_stack([dx[s] for s in STATES]).tolist(),
        "cases": cases,
    }
    with open(args.out, "w") as f:
        json.dump(fixture, f, separators=(",", ":"))
        f.write("\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
