#!/usr/bin/env bash
# Re-identify the shipped M100 models (models/sindy_m100.json, models/pd_m100.json) from the
# paper's logs in ../shared/flights/m100, runs 1-5 (run 7 is held out for docs/identification.md),
# then regenerate their crates with scripts/regenerate.sh. See docs/identification.md.
set -euo pipefail
cd "$(dirname "$0")/.."
M=../shared/flights/m100
if [ ! -d "$M" ]; then
    echo "identify_m100: $M not found (the paper's logs sit beside the project in CI)" >&2
    exit 1
fi
cargo build --release -q -p uavgen
uavgen=target/release/uavgen
TRAIN=()
for r in 1 2 3 4 5; do TRAIN+=(--log "$M/m100_run$r.csv"); done
# The shipped models are identified with identify's defaults (input delays and lags estimated,
# stale rows interpolated, BIC per row, the ridge ladder) except for the SINDy sweep: thresholds
# 16 … 64 instead of 0.5 … 256. Both pass the horizon check; on run 7 the shipped sweep predicts
# better over the horizon (overall RMSE 0.090 against 0.168; docs/identification.md).
# SINDy: physics library, STLSQ, per-row BIC (effective sample count) over this sweep, then
# rows moved to sparser values until one MPC horizon stays bounded.
$uavgen identify --method sindy "${TRAIN[@]}" --sweep-values 16,20,24,32,40,48,64 \
    --name sindy_m100 --out models/sindy_m100.json --force
# PD: bounded least squares, m = 2.4 kg, inertias 0.05, 0.05, 0.09 kg m² (docs/pd-fit.md).
$uavgen identify --method pd "${TRAIN[@]}" --targets integral --name pd_m100 \
    --out models/pd_m100.json --force
