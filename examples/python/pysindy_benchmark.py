#!/usr/bin/env python3
"""uavgen's Model.simulate against PySINDy's SINDy.simulate on the same fitted model (docs/python.md,
"PySINDy").

The model is tests/test_pysindy.py's: 3 states, 2 inputs, PySINDy 2.1 GeneralizedLibrary of a
degree-2 PolynomialLibrary, a FourierLibrary and an IdentityLibrary, fitted by STLSQ; converted with
``Model.from_pysindy``. Each simulates 1 s from the same x0 under the same inputs:

- uavgen: ``model.simulate(x0, U, dt)``, fixed-step RK4 with the inputs held over each sample (the
  generated crate's discretisation; substeps by the automatic rule), best of --repeat runs;
- PySINDy default: ``model.simulate(x0, t, u=U)`` — LSODA at rtol = atol = 1e-12, inputs
  interpolated by a cubic spline (PySINDy's defaults);
- PySINDy, the comparison setting: the inputs held (zero-order hold, a callable ``u``) and DOP853 at
  rtol = atol = 1e-10, which is what tests/test_pysindy.py compares uavgen's states with (1e-6).

Run (from the repository root, the package and pysindy installed)::

    python examples/python/pysindy_benchmark.py [--rate 100] [--seconds 1] [--repeat 200]
"""

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "generator" / "python" / "tests"))
import test_pysindy as fixture  # noqa: E402  (the fitted model and its inputs)

import uavgen  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate", type=float, default=100.0, help="samples per second")
    ap.add_argument("--seconds", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args()
    model, _, _ = fixture.fitted.__wrapped__()
    ours = uavgen.Model.from_pysindy(model, name="bench")
    dt = 1.0 / args.rate
    n = int(round(args.seconds * args.rate))
    t = np.arange(n + 1) * dt
    U = fixture.inputs(np.floor(t / 0.25) * 0.25)  # commands stepping every 0.25 s
    x0 = np.array([0.5, -0.3, 0.2])

    best = math.inf
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        xs = fixture.simulate_states(ours, x0, U[:-1], dt)
        best = min(best, time.perf_counter() - t0)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        default = model.simulate(x0, t, u=U)
        t_default = time.perf_counter() - t0
        t0 = time.perf_counter()
        held = model.simulate(x0, t, u=fixture.zoh(t, U[:-1]),
                              integrator_kws={"method": "DOP853", "rtol": 1e-10, "atol": 1e-10})
        t_held = time.perf_counter() - t0
    print(f"{n} samples of {dt:g} s, {len(model.get_feature_names())} PySINDy features")
    print(f"uavgen Model.simulate (RK4, held inputs): {best * 1e3:.3f} ms (best of {args.repeat})")
    print(f"PySINDy simulate, defaults (LSODA 1e-12, cubic inputs): {t_default:.2f} s "
          f"= {t_default / best:.0f}x uavgen")
    print(f"PySINDy simulate, held inputs, DOP853 1e-10: {t_held:.2f} s = {t_held / best:.0f}x uavgen; "
          f"max |x_uavgen - x_pysindy| = {np.max(np.abs(xs - held)):.2e}")
    print(f"(PySINDy defaults vs held inputs: max difference {np.max(np.abs(default - held[:len(default)])):.2e}, "
          f"the interpolation's effect)")


if __name__ == "__main__":
    main()
