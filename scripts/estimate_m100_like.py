#!/usr/bin/env python3
"""Estimate the effect magnitudes of plants/m100_like.json from the real M100 logs.

Usage (from the repository root; Python 3.11 with numpy):

    python3 scripts/estimate_m100_like.py [--flights ../shared/flights/m100] [--json out.json]
    python3 scripts/estimate_m100_like.py --logs sim.csv [...]   # the same estimates on other logs,
                                                                  # e.g. a simulated m100_like log

Deterministic (no random numbers). Prints one table per estimate and, with --json, writes the
numbers. docs/simulate.md explains each method and lists the values it gave; the plant file rounds
them. Every log row whose 12 states equal the previous row's is *stale* (sample-and-hold, see
docs/logs.md) and is left out of the fits as a target.

Estimates:
  1. stale-sample fraction f  → sample_hold.probability p = f / (1 − f) with max_run 1
     (the logs never repeat a state twice in a row).
  2. sensor noise per state group → sensor_noise: residuals of a local cubic fitted to 9 fresh
     samples around each fresh sample (their own time stamps), divided by √(1 − leverage).
  3. command-to-response delay and motor lag → latency.per_channel, motor_lag: the simulator's
     own linearised loops (roll/pitch: φ̈ = a, a = τ-lagged kp(K u(t − d) − φ) − kd φ̇ with
     kp = 144, kd = 19.2; u_vz: v̇ = τ-lagged k_vz (K u(t − d) − v); yaw: the yaw loop with its
     set-point integrator and feed-forward, kp = 6, kd = 4.9) run open loop for 1 s (30
     samples) from every fresh sample on the logged commands; d on a 1/210 s grid, τ on a grid, K
     (and k_vz) fitted; the pooled RMS over all six runs is minimised.
  4. drag → linear_drag: the horizontal acceleration (Savitzky-Golay derivative of the fresh
     velocity samples) minus what the tilt gives (g tan θ forward, −g tan φ / cos θ sideways, in
     the heading frame) regressed on the heading-frame velocity, a = −d v, through the origin,
     over samples with tilt < 0.05 rad ("deceleration at zero tilt") and over all samples.
"""

import argparse
import json
import os
import sys

import numpy as np

STATES = ["x", "y", "z", "roll", "pitch", "yaw", "vx", "vy", "vz", "roll_rate", "pitch_rate", "yaw_rate"]
RUNS = ["m100_run1.csv", "m100_run2.csv", "m100_run3.csv", "m100_run4.csv", "m100_run5.csv", "m100_run7.csv"]
G = 9.81
SUB = 7  # fine steps per sample in the loop fits (the plants' 210 Hz at 30 Hz)
HORIZON = 30


def load(path):
    lines = [l for l in open(path) if l.strip() and not l.startswith("#")]
    names = lines[0].strip().split(",")
    a = np.array([[float(v) for v in l.split(",")] for l in lines[1:]])
    d = {n: a[:, i] for i, n in enumerate(names)}
    d["yaw"] = np.unwrap(d["yaw"])
    x = np.column_stack([d[s] for s in STATES])
    stale = np.zeros(len(a), bool)
    stale[1:] = np.all(x[1:] == x[:-1], axis=1)
    d["stale"] = stale
    d["dt"] = float(np.median(np.diff(d["t"])))
    d["name"] = os.path.basename(path)
    return d


# 1. stale samples -------------------------------------------------------------------------------

def stale_fraction(runs):
    rows = sum(len(r["t"]) for r in runs)
    stale = sum(int(r["stale"].sum()) for r in runs)
    longest = 0
    for r in runs:
        run = 0
        for s in r["stale"]:
            run = run + 1 if s else 0
            longest = max(longest, run)
    per_run = {r["name"]: float(r["stale"].mean()) for r in runs}
    f = stale / rows
    return {"fraction": f, "per_run": per_run, "longest_run": longest, "probability_max_run_1": f / (1 - f)}


# 2. noise ---------------------------------------------------------------------------------------

def local_poly_residuals(t, y, window=9, order=3):
    """Residual at the centre of a local polynomial fit / sqrt(1 - leverage), per centre sample."""
    h = window // 2
    out = []
    for k in range(h, len(t) - h):
        tt = t[k - h:k + h + 1] - t[k]
        A = np.vander(tt, order + 1)
        pinv = np.linalg.pinv(A)
        hat_row = A[h] @ pinv  # the centre row of the hat matrix
        r = y[k] - hat_row @ y[k - h:k + h + 1]
        lev = hat_row[h]
        out.append(r / np.sqrt(max(1 - lev, 1e-9)))
    return np.array(out)


def noise(runs):
    groups = {"pos": ["x", "y", "z"], "att": ["roll", "pitch", "yaw"], "vel": ["vx", "vy", "vz"],
              "rate": ["roll_rate", "pitch_rate", "yaw_rate"]}
    result = {}
    for g, cols in groups.items():
        per_state = {}
        for c in cols:
            res = []
            for r in runs:
                fresh = ~r["stale"]
                res.append(local_poly_residuals(r["t"][fresh], r[c][fresh]))
            res = np.concatenate(res)
            # Robust sigma (MAD) and plain RMS.
            per_state[c] = {"mad_sigma": float(1.4826 * np.median(np.abs(res - np.median(res)))),
                            "rms": float(np.sqrt(np.mean(res ** 2)))}
        result[g] = {"per_state": per_state,
                     "sigma": float(np.median([v["mad_sigma"] for v in per_state.values()]))}
    return result


# 3. delay and lag -------------------------------------------------------------------------------

def loop_response(channel, r, starts, delay_steps, tau, gain_param):
    """Open-loop response of the linearised loop over HORIZON samples from each start: returns
    (free, forced) so that prediction = free + K * forced (linear in the command gain K)."""
    dt = r["dt"]
    h = dt / SUB
    n = len(starts)
    u_name = {"roll": "u_roll", "pitch": "u_pitch", "vz": "u_vz", "yaw_rate": "u_yaw_rate"}[channel]
    u = r[u_name]
    out = []
    for k_scale in (0.0, 1.0):
        if channel in ("roll", "pitch"):
            kp, kd = 144.0, 19.2
            y = r[channel][starts].copy()
            yd = r[channel + "_rate"][starts].copy()
            act = kp * (k_scale * u[starts] - y) - kd * yd if tau > 0 else None
        elif channel == "vz":
            k = gain_param
            y = r["vz"][starts].copy()
            act = k * (k_scale * u[starts] - y) if tau > 0 else None
        else:
            kp, kd = 6.0, 4.9
            w = r["yaw_rate"][starts].copy()
            e = np.zeros(n)  # yaw minus set-point
            act = (-kp * e + kd * k_scale * u[starts] - kd * w) if tau > 0 else None
        pred = np.zeros((n, HORIZON))
        for j in range(HORIZON):
            for s in range(SUB):
                q = j * SUB + s - delay_steps
                idx = np.clip(starts + np.floor_divide(q, SUB), 0, len(u) - 1)
                uu = k_scale * u[idx]
                if channel in ("roll", "pitch"):
                    cmd = kp * (uu - y) - kd * yd
                    act = cmd if tau <= 0 else act + (h / tau) * (cmd - act)
                    yd = yd + h * act
                    y = y + h * yd
                elif channel == "vz":
                    cmd = k * (uu - y)
                    act = cmd if tau <= 0 else act + (h / tau) * (cmd - act)
                    y = y + h * act
                else:
                    cmd = -kp * e + kd * uu - kd * w
                    act = cmd if tau <= 0 else act + (h / tau) * (cmd - act)
                    w = w + h * act
                    e = e + h * (w - uu)
            pred[:, j] = w if channel == "yaw_rate" else y
        out.append(pred)
    free, with_u = out
    return free, with_u - free


def fit_channel(channel, runs, delays, taus, gains=(None,)):
    data = []
    for r in runs:
        starts = np.array([k for k in range(20, len(r["t"]) - HORIZON - 1) if not r["stale"][k]])
        idx = starts[:, None] + np.arange(1, HORIZON + 1)[None, :]
        data.append((r, starts, r[channel][idx], ~r["stale"][idx]))
    best = None
    table = []
    for tau in taus:
        for g in gains:
            for d in delays:
                A, B = [], []
                for r, starts, meas, mask in data:
                    free, forced = loop_response(channel, r, starts, d, tau, g)
                    A.append(forced[mask])
                    B.append((meas - free)[mask])
                A, B = np.concatenate(A), np.concatenate(B)
                K = float(A @ B / (A @ A))
                rms = float(np.sqrt(np.mean((B - K * A) ** 2)))
                table.append((rms, d / (SUB * 30.0), tau, g, K))
                if best is None or rms < best[0]:
                    best = (rms, d / (SUB * 30.0), tau, g, K)
    return best, table


def delays_and_lag(runs):
    delays = list(range(0, 43, 1))  # 0 .. 0.2 s in 1/210 s
    taus = [0.0, 0.02, 0.04, 0.06, 0.08]
    res = {}
    for ch, gains in [("roll", (None,)), ("pitch", (None,)), ("vz", (3.0, 3.25, 3.5, 3.75, 4.0)), ("yaw_rate", (None,))]:
        best, table = fit_channel(ch, runs, delays, taus, gains)
        by_tau = {}
        for rms, d, tau, g, K in table:
            if tau not in by_tau or rms < by_tau[tau][0]:
                by_tau[tau] = (rms, d, g, K)
        res[ch] = {
            "delay_s": best[1], "motor_lag_s": best[2], "k_vz": best[3], "gain": best[4], "rms": best[0],
            "best_by_motor_lag": {str(t): {"rms": v[0], "delay_s": v[1], "k_vz": v[2], "gain": v[3]}
                                  for t, v in sorted(by_tau.items())},
        }
    # One motor lag for all channels: the τ minimising the sum over roll, pitch, vz of rms / best rms.
    score = {}
    for tau in taus:
        score[tau] = sum(res[ch]["best_by_motor_lag"][str(tau)]["rms"] / res[ch]["rms"] for ch in ("roll", "pitch", "vz"))
    tau = min(score, key=score.get)
    res["joint_motor_lag_s"] = tau
    res["joint_score"] = {str(k): v for k, v in score.items()}
    return res


# 4. drag ----------------------------------------------------------------------------------------

def savgol_derivative(t, y, window=9, order=3):
    h = window // 2
    d = np.full(len(t), np.nan)
    for k in range(h, len(t) - h):
        tt = t[k - h:k + h + 1] - t[k]
        coef = np.polyfit(tt, y[k - h:k + h + 1], order)
        d[k] = coef[-2]
    return d


def drag(runs):
    rows = {"small_tilt": [], "all": []}
    for r in runs:
        fresh = ~r["stale"]
        t = r["t"][fresh]
        s = {c: r[c][fresh] for c in STATES}
        ax, ay = savgol_derivative(t, s["vx"]), savgol_derivative(t, s["vy"])
        c, sn = np.cos(s["yaw"]), np.sin(s["yaw"])
        afx, afy = c * ax + sn * ay, -sn * ax + c * ay
        vfx, vfy = c * s["vx"] + sn * s["vy"], -sn * s["vx"] + c * s["vy"]
        tx = G * np.tan(s["pitch"])
        ty = -G * np.tan(s["roll"]) / np.cos(s["pitch"])
        tilt = np.arccos(np.cos(s["roll"]) * np.cos(s["pitch"]))
        ok = np.isfinite(afx)
        for key, sel in [("small_tilt", ok & (tilt < 0.05)), ("all", ok)]:
            rows[key].append(np.column_stack([afx - tx, vfx, afy - ty, vfy, tilt])[sel])
    out = {}
    for key, parts in rows.items():
        m = np.concatenate(parts)
        moving_x = np.abs(m[:, 1]) > 0.3
        moving_y = np.abs(m[:, 3]) > 0.3
        dx = -float(m[moving_x, 0] @ m[moving_x, 1] / (m[moving_x, 1] @ m[moving_x, 1]))
        dy = -float(m[moving_y, 2] @ m[moving_y, 3] / (m[moving_y, 3] @ m[moving_y, 3]))
        out[key] = {"d_forward": dx, "d_sideways": dy, "samples": [int(moving_x.sum()), int(moving_y.sum())]}
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    here = os.path.dirname(os.path.abspath(__file__))
    ap.add_argument("--flights", default=os.path.join(here, "..", "..", "shared", "flights", "m100"))
    ap.add_argument("--logs", nargs="+", help="estimate from these logs instead of the M100 runs")
    ap.add_argument("--json", help="also write the estimates as JSON")
    args = ap.parse_args()
    paths = args.logs or [os.path.join(args.flights, r) for r in RUNS]
    missing = [p for p in paths if not os.path.exists(p)]
    if missing:
        sys.exit(f"missing M100 logs: {', '.join(missing)}")
    runs = [load(p) for p in paths]

    est = {"runs": [os.path.basename(p) for p in paths]}
    est["stale"] = stale_fraction(runs)
    s = est["stale"]
    print(f"1. stale samples: {100 * s['fraction']:.1f} % of {sum(len(r['t']) for r in runs)} rows "
          f"(per run {', '.join(f'{100 * v:.1f}' for v in s['per_run'].values())} %), longest run {s['longest_run']}"
          f" -> sample_hold probability {s['probability_max_run_1']:.3f} with max_run 1")

    est["noise"] = noise(runs)
    print("2. noise (local cubic over 9 fresh samples, MAD sigma per state; group = median):")
    for g, v in est["noise"].items():
        per = ", ".join(f"{c} {x['mad_sigma']:.4f}" for c, x in v["per_state"].items())
        print(f"   {g:<5} {v['sigma']:.4f}   ({per})")

    est["loops"] = delays_and_lag(runs)
    print("3. delay and motor lag (the simulator's loops, open loop over 1 s, pooled over the runs):")
    for ch in ("roll", "pitch", "vz", "yaw_rate"):
        v = est["loops"][ch]
        extra = f", k_vz {v['k_vz']}" if v["k_vz"] else ""
        print(f"   {ch:<9} delay {v['delay_s']:.3f} s, motor lag {v['motor_lag_s']:.2f} s, gain {v['gain']:.3f}{extra}, rms {v['rms']:.4f}")
        for tau, b in v["best_by_motor_lag"].items():
            extra = f", k_vz {b['k_vz']}" if b["k_vz"] else ""
            print(f"       motor lag {float(tau):.2f}: delay {b['delay_s']:.3f} s, rms {b['rms']:.5f}{extra}")
    print(f"   one motor lag for roll, pitch, vz: {est['loops']['joint_motor_lag_s']:.2f} s")

    est["drag"] = drag(runs)
    print("4. linear drag (heading-frame acceleration not explained by the tilt, vs velocity):")
    for k, v in est["drag"].items():
        print(f"   {k:<10} d forward {v['d_forward']:.3f} 1/s, sideways {v['d_sideways']:.3f} 1/s ({v['samples']} samples)")

    if args.json:
        with open(args.json, "w") as f:
            json.dump(est, f, indent=2)
            f.write("\n")


if __name__ == "__main__":
    main()
