#!/usr/bin/env bash
# Regenerate every checked-in crate under generated/ from models/ with the
# options recorded here. CI runs this and then `git diff --exit-code generated/`.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p uavgen
uavgen=${CARGO_TARGET_DIR:-target}/release/uavgen
$uavgen --model models/pd_paper.json --horizon 30 --out generated/pd_paper
$uavgen --model models/pd_hover.json --horizon 30 --out generated/pd_hover
$uavgen --model models/pd_hover.json --horizon 30 --float f32 --crate-name pd_hover_f32 --out generated/pd_hover_f32
$uavgen --model models/sindy_m100.json --horizon 30 --c-api --out generated/sindy_m100
$uavgen --model models/pd_m100.json --horizon 30 --out generated/pd_m100
# The stage-wise (Riccati interior-point) solver on the same models (`--qp riccati`; `auto` picks
# the condensed one at these sizes, docs/mpc.md), with the default options (input-rate weight included):
# tested against the generic reference like the others.
$uavgen --model models/sindy_m100.json --horizon 30 --qp riccati --c-api --crate-name sindy_m100_riccati --out generated/sindy_m100_riccati
