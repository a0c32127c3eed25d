#!/usr/bin/env bash
# The sim-to-real protocol of docs/diagnosis.md: base models from a simulator (uavgen simulate on
# plants/nominal.json; RotorPy's nominal logs), diagnosed against the real M100 runs 1-5 with run 7
# held out; R = the model identified on runs 1-5 with the same (default) settings. Also the
# m100_like check (a nominal-plant model diagnosed against m100_like flights). Prints the figures
# docs/diagnosis.md quotes; writes everything under $OUT (default target/sim_to_real).
set -euo pipefail
cd "$(dirname "$0")/.."
M=../shared/flights/m100
R=../shared/flights
if [ ! -d "$M" ]; then
    echo "sim_to_real: $M not found (the paper's logs sit beside the project in CI)" >&2
    exit 1
fi
OUT=${OUT:-target/sim_to_real}
mkdir -p "$OUT"
cargo build --release -q -p uavgen
U=target/release/uavgen
TRAIN=()
for r in 1 2 3 4 5; do TRAIN+=(--log "$M/m100_run$r.csv"); done
HOLD="$M/m100_run7.csv"
horizon() { # model -> overall horizon RMSE on run 7 (default options: stale rows interpolated)
    $U evaluate --model "$1" --log "$HOLD" --json "$OUT/eval.json" --force >/dev/null 2>&1
    python3 -c "import json;print(round(json.load(open('$OUT/eval.json'))['horizon']['metrics']['overall_rmse'],4))"
}
# The identification settings of base models and R alike: those of the shipped sindy_m100
# (scripts/identify_m100.sh): identify's defaults (input delays estimated, stale rows interpolated,
# BIC, the ridge ladder) with the sweep 16 ... 64. (With the full default sweep the SINDy model of
# runs 1-5 passes its horizon check but predicts run 7 worse than the base models: docs/identification.md.)
SETTINGS=(${SETTINGS_OVERRIDE:-})
# R: identified on runs 1-5 with these settings.
$U identify --method sindy "${TRAIN[@]}" "${SETTINGS[@]}" --out "$OUT/R.json" --force >/dev/null 2>&1
RH=$(horizon "$OUT/R.json")
# Base models: the nominal simulator (180 s excitation) and RotorPy's nominal training log.
$U simulate --plant plants/nominal.json --profile excite --duration 180 --seed 11 --out "$OUT/nominal.csv" --force >/dev/null
$U identify --method sindy --log "$OUT/nominal.csv" "${SETTINGS[@]}" --out "$OUT/base_sim.json" --force >/dev/null 2>&1
$U identify --method sindy --log "$R/rotorpy_nominal_train.csv" "${SETTINGS[@]}" --out "$OUT/base_rotorpy.json" --force >/dev/null 2>&1
for b in sim rotorpy; do
    echo "== base: $b"
    $U diagnose --model "$OUT/base_$b.json" "${TRAIN[@]}" --holdout "$HOLD" --out "$OUT/diag_$b" --force 2>/dev/null
    B=$(horizon "$OUT/base_$b.json")
    C=$(horizon "$OUT/diag_$b/corrected.json")
    python3 -c "b,c,r=$B,$C,$RH;print(f'B {b}  C {c}  R {r}  (B-C)/(B-R) = {(b-c)/(b-r):.2f}')"
done
echo "== m100_like: base from nominal flights, diagnosed against m100_like flights"
$U simulate --plant plants/m100_like.json --profile excite --duration 180 --seed 21 --out "$OUT/m100_like_train.csv" --force >/dev/null
$U simulate --plant plants/m100_like.json --profile excite --duration 90 --seed 22 --out "$OUT/m100_like_test.csv" --force >/dev/null
$U diagnose --model "$OUT/base_sim.json" --log "$OUT/m100_like_train.csv" --holdout "$OUT/m100_like_test.csv" \
    --out "$OUT/diag_m100_like" --force 2>/dev/null
python3 - "$OUT/diag_m100_like/corrected.json" <<'PY'
import json, sys
c = json.load(open(sys.argv[1]))["corrections"]
truth = {"u_vz": 0.133, "u_roll": 0.076, "u_pitch": 0.09, "u_yaw_rate": 0.176}
for u, t in truth.items():
    d = c.get("latency", {}).get(u, 0.0) + c.get("actuator_lag", {}).get(u, 0.0)
    print(f"{u}: delay + lag {d:.3f} s against {t} s ({100 * (d / t - 1):+.0f} %)")
drag = c.get("linear_drag", {}).get("xy")
print(f"linear drag xy: {drag} against 0.084/0.078 1/s" if drag is not None else "drag: not named")
PY
