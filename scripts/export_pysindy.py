#!/usr/bin/env python3
"""Export a fitted PySINDy model to the JSON that ``uavgen import-pysindy`` reads.

Library use::

    from export_pysindy import export
    export(model, "model_pysindy.json", targets=["vx", "vz"], kinematic=[["x", "vx"]])

then ``uavgen import-pysindy --input model_pysindy.json --name NAME --out model.json``.

Written JSON (keys in this order)::

    {
      "feature_names": model.get_feature_names(),   # library term names, e.g. "1", "vx",
                                                    # "vx^2", "vx u_vz", "sin(pitch)"
      "coefficients": model.coefficients().tolist(),# one row per target, one column per feature
      "targets": [...],        # state name whose time derivative each row gives
      "kinematic": [[state, derivative_state], ...],   # optional: exact rows state' = other state
      "inputs": [...],         # optional: names of the model inputs
      "pysindy_version": "...",
      "generator": "scripts/export_pysindy.py"
    }

``targets`` defaults to the first ``n_rows`` names of ``model.feature_names`` (PySINDy fits
one row per state column ``x``; control inputs ``u`` come after them). Variable names must
be uavgen's state/input names (pass ``feature_names=`` to ``SINDy.fit``) so the terms can be
matched.

CLI demo (writes the test fixture)::

    python3 scripts/export_pysindy.py --out tests/fixtures/pysindy_export.json

fits a real PySINDy model on a small synthetic data set (400 samples, dt = 0.02 s) of a toy
vehicle whose signals carry uavgen's 16 variable names, targets vx and vz only:

    vx' = 9.81 sin(pitch) - 0.4 vx
    vz' = 2.0 u_vz - 2.0 vz - 0.5 vz^2 + 0.3 vx u_vz

(the square and product terms are there only to exercise the term parser). PySINDy sees
x = [vx, vz] as states and the other 14 variables (remaining states and the 4 inputs) as
control inputs ``u``, with ``feature_names`` = those 16 names. The library is a
GeneralizedLibrary of PolynomialLibrary(degree=2) over [vx, vz, u_vz] and a CustomLibrary
with sin/cos over [roll, pitch] whose names are "sin(roll)" etc. (instead of
FourierLibrary's "sin(1 roll)"). Exact derivatives from the simulation are passed as
``x_dot``; STLSQ(threshold=0.1, alpha=1e-8) gives a sparse, exact recovery (PySINDy's
default ridge alpha=0.05 on these unnormalised, nearly collinear columns - "1", cos(roll),
cos(pitch) at small angles - smears the vx row over a dozen terms). Determinism: fixed
signals, no random numbers.
"""

import argparse
import json
import os

import numpy as np

STATES = ["x", "y", "z", "roll", "pitch", "yaw",
          "vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"]
INPUTS = ["u_vz", "u_roll", "u_pitch", "u_yaw_rate"]
GENERATOR = "scripts/export_pysindy.py"


def export(model, path, targets=None, kinematic=None, inputs=None):
    """Dump a fitted ``pysindy.SINDy`` model to ``path`` (see module docstring)."""
    import pysindy

    coefficients = np.asarray(model.coefficients(), dtype=float)
    feature_names = list(model.get_feature_names())
    if coefficients.shape[1] != len(feature_names):
        raise ValueError("coefficients and feature names disagree")
    if targets is None:
        targets = list(model.feature_names[: coefficients.shape[0]])
    targets = list(targets)
    if len(targets) != coefficients.shape[0]:
        raise ValueError(f"{len(targets)} targets for {coefficients.shape[0]} coefficient rows")
    out = {
        "feature_names": feature_names,
        "coefficients": [[float(v) + 0.0 for v in row] for row in coefficients],  # no -0.0
        "targets": targets,
    }
    if kinematic is not None:
        out["kinematic"] = [[str(a), str(b)] for a, b in kinematic]
    if inputs is not None:
        out["inputs"] = list(inputs)
    out["pysindy_version"] = pysindy.__version__
    out["generator"] = GENERATOR
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    with open(path, "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    return out


# --------------------------------------------------------------------------- demo
def toy_rhs(s, u):
    """Toy vehicle. s: 12 states (uavgen order), u: 4 inputs. Returns ds/dt."""
    x, y, z, roll, pitch, yaw, vx, vy, vz, p, q, r = s
    u_vz, u_roll, u_pitch, u_yaw_rate = u
    d = np.zeros(12)
    d[0:3] = [vx, vy, vz]
    d[3:6] = [p, q, r]                                      # Euler-angle rates
    d[6] = 9.81 * np.sin(pitch) - 0.4 * vx
    d[7] = -9.81 * np.sin(roll) - 0.4 * vy
    d[8] = 2.0 * u_vz - 2.0 * vz - 0.5 * vz ** 2 + 0.3 * vx * u_vz
    d[9] = 16.0 * (u_roll - roll) - 6.0 * p                 # attitude loops
    d[10] = 16.0 * (u_pitch - pitch) - 6.0 * q
    d[11] = 3.0 * (u_yaw_rate - r)
    return d


def toy_inputs(t):
    return np.array([
        0.8 * np.sin(0.7 * t) + 0.3 * np.sin(2.3 * t + 0.5),      # u_vz
        0.30 * np.sin(0.9 * t + 1.0) + 0.10 * np.sin(2.9 * t),     # u_roll
        0.35 * np.sin(1.3 * t) + 0.15 * np.sin(3.1 * t + 0.4),     # u_pitch
        0.5 * np.sin(0.4 * t),                                     # u_yaw_rate
    ])


def simulate(n=400, dt=0.02, substeps=10):
    t = np.arange(n) * dt
    S = np.zeros((n, 12))
    s = np.zeros(12)
    s[6], s[8] = 0.5, -0.2
    h = dt / substeps
    for k in range(n):
        S[k] = s
        for j in range(substeps):
            tk = t[k] + j * h
            k1 = toy_rhs(s, toy_inputs(tk))
            k2 = toy_rhs(s + 0.5 * h * k1, toy_inputs(tk + 0.5 * h))
            k3 = toy_rhs(s + 0.5 * h * k2, toy_inputs(tk + 0.5 * h))
            k4 = toy_rhs(s + h * k3, toy_inputs(tk + h))
            s = s + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    U = np.array([toy_inputs(tk) for tk in t])
    dS = np.array([toy_rhs(S[k], U[k]) for k in range(n)])
    return t, S, U, dS


def demo(out_path):
    import pysindy as ps

    t, S, U, dS = simulate()
    targets = ["vx", "vz"]
    others = [v for v in STATES if v not in targets] + INPUTS
    names = targets + others                                # the 16 uavgen names
    data = {v: S[:, STATES.index(v)] for v in STATES}
    data.update({v: U[:, INPUTS.index(v)] for v in INPUTS})
    X = np.column_stack([data[v] for v in targets])
    Xu = np.column_stack([data[v] for v in others])
    X_dot = np.column_stack([dS[:, STATES.index(v)] for v in targets])

    poly = ps.PolynomialLibrary(degree=2, include_bias=True)
    trig = ps.CustomLibrary(
        library_functions=[lambda a: np.sin(a), lambda a: np.cos(a)],
        function_names=[lambda s: f"sin({s})", lambda s: f"cos({s})"],
    )
    idx = {v: i for i, v in enumerate(names)}
    library = ps.GeneralizedLibrary(
        [poly, trig],
        inputs_per_library=[[idx["vx"], idx["vz"], idx["u_vz"]], [idx["roll"], idx["pitch"]]],
    )
    model = ps.SINDy(feature_library=library, optimizer=ps.STLSQ(threshold=0.1, alpha=1e-8))
    model.fit(X, t=t, x_dot=X_dot, u=Xu, feature_names=names)
    model.print()
    out = export(model, out_path, targets=targets, inputs=INPUTS)
    print(f"wrote {out_path}: {len(out['feature_names'])} features x {len(targets)} rows, "
          f"pysindy {out['pysindy_version']}")
    print("feature names:", out["feature_names"])


def main():
    ap = argparse.ArgumentParser(description="Fit a toy PySINDy model and export it (demo).")
    ap.add_argument("--out", default="tests/fixtures/pysindy_export.json")
    args = ap.parse_args()
    demo(args.out)


if __name__ == "__main__":
    main()
