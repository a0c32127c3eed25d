#!/usr/bin/env bash
# Run every test of uavgen: the README's test command, and what CI runs.
#  1. installs what the tests need (the thumbv7em target, clippy, rustfmt);
#  2. checks formatting and clippy;
#  3. regenerates generated/ and fails if the checked-in crates differ;
#  4. builds the no_std crates, the C ABI staticlib and the firmware example for thumbv7em-none-eabihf
#     (no panic path, empty .data), and checks the functions' thumbv7em stack bounds against their limits;
#     runs the firmware example's closed loop on emulated Cortex-M4 and M7 cores (QEMU);
#  5. installs the Python package (pip install ./generator) in a fresh venv and runs its pytest suite;
#  6. runs all unit, property, reference and CLI tests (release build).
set -euo pipefail
cd "$(dirname "$0")/.."

echo "== setup"
rustup target add thumbv7em-none-eabihf >/dev/null
rustup component add clippy rustfmt >/dev/null 2>&1 || true
# The Cortex-M toolchain (C ABI link, stack bounds) from Debian's packages, where we may install.
if ! command -v arm-none-eabi-gcc >/dev/null && command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    (apt-get update -qq && apt-get install -y -qq gcc-arm-none-eabi) >/dev/null 2>&1 ||
        echo "could not install gcc-arm-none-eabi: the Cortex-M link and stack-bound steps will be skipped" >&2
fi
# QEMU's system emulator for the on-target closed loop (Debian's package), likewise.
if ! command -v qemu-system-arm >/dev/null && command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    (apt-get update -qq && apt-get install -y -qq --no-install-recommends qemu-system-arm) >/dev/null 2>&1 ||
        echo "could not install qemu-system-arm: the on-target closed loop will be skipped" >&2
fi

echo "== format and lints"
cargo fmt --all -- --check
cargo clippy --workspace --all-targets --release -q -- -D warnings

echo "== generated/ is up to date"
scripts/regenerate.sh
if ! git diff --exit-code --stat -- generated/ || [ -n "$(git status --porcelain -- generated/)" ]; then
    echo "generated/ differs from what the generator produces: run scripts/regenerate.sh and commit" >&2
    git status --porcelain -- generated/ >&2
    exit 1
fi

echo "== no_std crates build for thumbv7em-none-eabihf"
cargo build --release -q --target thumbv7em-none-eabihf \
    -p uavgen-templates -p uavgen-runtime -p pd_paper -p pd_hover -p pd_hover_f32 -p sindy_m100 -p pd_m100 -p sindy_m100_riccati

echo "== the C ABI staticlib builds for thumbv7em-none-eabihf (docs/c-api.md)"
cargo build --release -q --target thumbv7em-none-eabihf -p sindy_m100_capi
# Where cargo puts the workspace's builds (CARGO_TARGET_DIR, relative to the repository, or target/),
# made absolute for make -C below.
target_dir=$(realpath -m "${CARGO_TARGET_DIR:-target}")
capi=$target_dir/thumbv7em-none-eabihf/release/libsindy_m100_capi.a
test -s "$capi" || { echo "$capi was not built" >&2; exit 1; }
if command -v llvm-nm >/dev/null; then
    # The symbol table once (a `grep -q` on the pipe would stop llvm-nm early: SIGPIPE under pipefail).
    # An older llvm-nm cannot read the LLVM bitcode some archive members carry and exits 1 after
    # listing the rest; the symbols are then still checked one by one below.
    defined=$(llvm-nm --defined-only "$capi" 2>/dev/null || true)
    for symbol in sindy_m100_init sindy_m100_prepare sindy_m100_feedback sindy_m100_shift sindy_m100_solve; do
        grep -q " T $symbol\$" <<<"$defined" ||
            { echo "$capi does not define $symbol" >&2; exit 1; }
    done
    echo "$capi defines the ABI's functions"
fi
if command -v arm-none-eabi-gcc >/dev/null && command -v make >/dev/null; then
    # A freestanding C program for Cortex-M7 (hard-float EABI) links against it, with no panic path.
    make -s -C examples/c cortex-m CARGO_TARGET_DIR="$target_dir"
    if grep -qi panic <<<"$(arm-none-eabi-nm "$target_dir/c-example/cortex_m.elf")"; then
        echo "examples/c/cortex_m.c: a panic path is linked in" >&2
        exit 1
    fi
else
    echo "arm-none-eabi-gcc or make not found: skipping the Cortex-M link of examples/c/cortex_m.c (Debian: gcc-arm-none-eabi)"
fi

echo "== firmware example links a generated solver (thumbv7em-none-eabihf, panic = abort)"
# Its own target directory (its own workspace and profile), whatever CARGO_TARGET_DIR says.
(cd runtime/firmware-example && cargo build --release -q --target-dir target)
if command -v llvm-nm >/dev/null; then
    for bin in sindy_m100 pd_hover_f32; do
        elf=runtime/firmware-example/target/thumbv7em-none-eabihf/release/$bin
        if grep -qi panic <<<"$(llvm-nm "$elf")"; then
            echo "$bin: a panic path is linked into the firmware (see llvm-objdump -d)" >&2
            exit 1
        fi
    done
    echo "no panic path linked into the firmware binaries"
    # The solver's state lives in .bss (zeroed RAM): a non-empty .data would be copied from flash
    # at start-up, i.e. the workspace stored twice (an emitted initialiser that is not all zeros).
    if command -v llvm-size >/dev/null; then
        for bin in sindy_m100 pd_hover_f32; do
            elf=runtime/firmware-example/target/thumbv7em-none-eabihf/release/$bin
            data=$(llvm-size -A "$elf" | awk '$1 == ".data" { print $2 }')
            if [ "${data:-0}" != 0 ]; then
                echo "$bin: .data is $data bytes (the solver's state belongs in .bss)" >&2
                exit 1
            fi
            llvm-size -A "$elf" | awk -v b="$bin" '$1 == ".text" || $1 == ".bss" { printf "%s %s %s B  ", b, $1, $2 } END { print "" }'
        done
    fi
else
    echo "llvm-nm not found: skipping the no-panic check of the firmware binaries"
fi

echo "== thumbv7em stack bounds within their limits (scripts/stack_bounds.sh, generated/stack-bounds.json)"
# Every Rust API and C ABI function of sindy_m100, sindy_m100_riccati and pd_hover_f32, bounded from
# the call graph of cortex-m7 builds (nightly: -Z emit-stack-sizes); fails when a bound grows past
# its limit (the figures the generated headers and READMEs quote).
if command -v arm-none-eabi-gcc >/dev/null && rustup toolchain list | grep -q '^nightly'; then
    scripts/stack_bounds.sh
else
    echo "arm-none-eabi-gcc or the nightly toolchain missing: skipping the stack bounds" >&2
fi

echo "== the closed loop on emulated Cortex-M4 and M7 (QEMU; scripts/target_bench.sh --ci)"
# The firmware example (feature qemu) on mps2-an386 and mps2-an500 under -icount: f32 on both, f64
# on the M7; fails on any feedback or reference error, a failed instruction-count calibration or a
# hang. Prints the per-step instruction counts (docs/benchmarks.md, "On the target").
if command -v qemu-system-arm >/dev/null; then
    scripts/target_bench.sh --ci
else
    echo "qemu-system-arm not found: skipping the on-target closed loop (Debian: qemu-system-arm)" >&2
fi

echo "== Python package: pip install ./generator in a fresh venv, pytest (docs/python.md)"
# The bindings (feature `python`) lint clean too; the package is built by maturin from PyPI (pip's
# build isolation) against the workspace's target directory, and its results are compared with the
# CLI's (the release binary built here).
cargo clippy -p uavgen --all-targets --release -q --features python -- -D warnings
cargo build --release -q -p uavgen
venv=$target_dir/pyvenv
rm -rf "$venv"
# venv (Debian: python3-venv), else virtualenv from PyPI.
python3 -m venv "$venv" 2>/dev/null || { python3 -m pip install -q --user virtualenv && python3 -m virtualenv -q "$venv"; }
"$venv/bin/pip" install -q --disable-pip-version-check ./generator pandas -r generator/python/requirements-test.txt
UAVGEN_BIN=$target_dir/release/uavgen CARGO_TARGET_DIR=$target_dir "$venv/bin/python" -m pytest -q generator/python/tests

echo "== tests"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
# Tests that need ../shared record themselves here when they skip (generator/tests/shared/mod.rs);
# where ../shared exists, a test that cannot find its files fails instead of skipping.
skipped_dir=${CARGO_TARGET_DIR:-target}/tmp/skipped
rm -rf "$skipped_dir"
if [ -d ../shared/flights ]; then export UAVGEN_REQUIRE_SHARED=1; fi
set +e
cargo test --workspace --release --no-fail-fast 2>&1 | tee "$log"
status=${PIPESTATUS[0]}
set -e
# One closing line over all test binaries (cargo prints one per binary); a skipped test is
# counted as skipped, not as passed.
skipped=0
if [ -d "$skipped_dir" ]; then
    skipped=$(find "$skipped_dir" -type f | wc -l)
    for f in "$skipped_dir"/*; do
        [ -f "$f" ] && echo "skipped: $(basename "$f") (needs $(cat "$f"))"
    done
fi
awk -v s="$skipped" '/^test result:/ { for (i = 1; i <= NF; i++) { if ($i ~ /^passed/) p += $(i-1); if ($i ~ /^failed/) f += $(i-1) } }
     END { printf "tests: %d passed, %d skipped, %d failed\n", p - s, s, f }' "$log"
exit "$status"
