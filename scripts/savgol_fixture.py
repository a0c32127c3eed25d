#!/usr/bin/env python3
"""Generate the scipy cross-check fixture for uavgen's Savitzky-Golay filter.

Writes generator/src/identify/preprocess/testdata/savgol_scipy.json, which the test
generator/tests/preprocess_metrics.rs compares against `uavgen::identify::preprocess::SavGol`
(agreement required to 1e-10).

The signal is deterministic (no random numbers): a sum of sinusoids, a quadratic trend and a
fast "chirp" term standing in for noise, sampled at dt = 0.05 s, 80 samples. For each
(window, order) pair the fixture holds scipy.signal.savgol_filter(y, window, order,
deriv=d, delta=dt, mode="interp") for d = 0 (smoothing), 1 and 2, and the interior
coefficients scipy.signal.savgol_coeffs(window, order, deriv=d, delta=dt, use="dot").
The input signal itself is stored in the fixture too, so the test does not recompute it.

Usage (from the repository root; needs numpy and scipy, e.g. `pip install numpy scipy`):

    python3 scripts/savgol_fixture.py

The output is deterministic for a given scipy version (floats are written with repr, which
round-trips exactly); the scipy and numpy versions used are recorded in the file.
"""

import json
import pathlib

import numpy as np
import scipy
import scipy.signal

DT = 0.05
N = 80
PAIRS = [(5, 2), (7, 0), (11, 3), (21, 4), (9, 6)]
DERIVS = [0, 1, 2]


def signal() -> np.ndarray:
    t = np.arange(N) * DT
    return np.sin(0.7 * t) + 0.3 * np.cos(2.3 * t + 0.4) + 0.05 * t**2 + 0.02 * np.sin(37.0 * t**2)


def main() -> None:
    y = signal()
    cases = []
    for window, order in PAIRS:
        for deriv in DERIVS:
            out = scipy.signal.savgol_filter(y, window, order, deriv=deriv, delta=DT, mode="interp")
            coeffs = scipy.signal.savgol_coeffs(window, order, deriv=deriv, delta=DT, use="dot")
            cases.append(
                {
                    "window": window,
                    "order": order,
                    "deriv": deriv,
                    "coefficients": [float(c) for c in coeffs],
                    "output": [float(v) for v in out],
                }
            )
    fixture = {
        "generator": "scripts/savgol_fixture.py",
        "scipy": scipy.__version__,
        "numpy": np.__version__,
        "mode": "interp",
        "dt": DT,
        "signal": [float(v) for v in y],
        "cases": cases,
    }
    root = pathlib.Path(__file__).resolve().parent.parent
    path = root / "generator/src/identify/preprocess/testdata/savgol_scipy.json"
    path.write_text(json.dumps(fixture, indent=1) + "\n")
    print(f"wrote {path.relative_to(root)}: {len(cases)} cases, {N} samples")


if __name__ == "__main__":
    main()
