#!/usr/bin/env bash
# The aircraft bed (issue 27; docs/simulate.md#the-aircraft-bed): flights of three vehicle classes of
# the project's own plants, each with and without heading excitation, as training and held-out sets.
#
#   class  plant                  rate    vehicle
#   nano   plants/nano.json       100 Hz  30 g Crazyflie class, stock-PID-like attitude loop
#   m100   plants/m100_like.json   30 Hz  2.9 kg DJI M100 class (effects estimated from the real logs)
#   px4    plants/px4_quad.json    50 Hz  1.5 kg PX4 x500 class, motor lag, offboard link delay
#
# Per class four logs, one segment each (seconds, seeds below):
#   train_excite.csv  profile excite              (all four inputs excited, heading turns)
#   train_hold.csv    profile excite-hold-heading (heading held, u_yaw_rate carries almost no signal)
#   test_excite.csv   held out, excite
#   test_hold.csv     held out, excite-hold-heading
# Seeds: class base B (nano 1000, m100 2000, px4 3000); train_excite B+1, train_hold B+2,
# test_excite B+3, test_hold B+4. Every log is a pure function of plant, profile, duration and seed.
#
# RotorPy's Crazyflie (the independent simulator) is the fourth class; its logs are committed in
# tests/data/rotorpy_cf/ (scripts/rotorpy_crazyflie.py regenerates them) and are not written here.
#
# Usage: scripts/aircraft_bed.sh [OUT]   (default target/aircraft_bed)
# Env:   TRAIN_S (seconds per training log, default 120), TEST_S (held-out, default 60),
#        CLASSES (default "nano m100 px4").
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/aircraft_bed}
TRAIN_S=${TRAIN_S:-120}
TEST_S=${TEST_S:-60}
CLASSES=${CLASSES:-"nano m100 px4"}
U=${UAVGEN:-target/release/uavgen}
if [ -z "${UAVGEN:-}" ]; then
    cargo build --release -q -p uavgen
fi

plant_of() {
    case "$1" in
        nano) echo plants/nano.json ;;
        m100) echo plants/m100_like.json ;;
        px4) echo plants/px4_quad.json ;;
        *) echo "aircraft_bed: unknown class '$1' (nano, m100, px4)" >&2; return 1 ;;
    esac
}
seed_of() {
    case "$1" in
        nano) echo 1000 ;;
        m100) echo 2000 ;;
        px4) echo 3000 ;;
    esac
}

for c in $CLASSES; do
    P=$(plant_of "$c")
    B=$(seed_of "$c")
    mkdir -p "$OUT/$c"
    $U simulate --quiet --plant "$P" --profile excite --duration "$TRAIN_S" --seed $((B + 1)) \
        --out "$OUT/$c/train_excite.csv" --force >/dev/null
    $U simulate --quiet --plant "$P" --profile excite-hold-heading --duration "$TRAIN_S" --seed $((B + 2)) \
        --out "$OUT/$c/train_hold.csv" --force >/dev/null
    $U simulate --quiet --plant "$P" --profile excite --duration "$TEST_S" --seed $((B + 3)) \
        --out "$OUT/$c/test_excite.csv" --force >/dev/null
    $U simulate --quiet --plant "$P" --profile excite-hold-heading --duration "$TEST_S" --seed $((B + 4)) \
        --out "$OUT/$c/test_hold.csv" --force >/dev/null
    echo "$c: $P, train ${TRAIN_S} s x2 (seeds $((B + 1)), $((B + 2))), held out ${TEST_S} s x2 (seeds $((B + 3)), $((B + 4))) -> $OUT/$c"
done
