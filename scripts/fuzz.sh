#!/usr/bin/env bash
# Fuzz every cargo-fuzz target (fuzz/, nightly) for SECONDS each (default 60), or only the named
# targets: scripts/fuzz.sh 1800, scripts/fuzz.sh 60 model log. A crash stops the run with
# libFuzzer's report; minimise it (cargo +nightly fuzz tmin TARGET ARTIFACT), fix it, and commit
# the artifact in fuzz/artifacts/TARGET/: generator/tests/fuzz_corpus.rs replays it on stable.
# See docs/testing.md.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
seconds=${1:-60}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(model log plant mpc_options pysindy import_ulog import_bag import_mcap import_dataflash import_csv)
fi
# libFuzzer writes new inputs into the first corpus directory: a scratch copy keeps the committed
# seeds small.
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
logs=target/fuzz-logs
mkdir -p "$logs"
cargo +nightly fuzz build -O
for t in "${targets[@]}"; do
    mkdir -p "$work/$t"
    cp corpus/"$t"/* "$work/$t/"
    echo "== $t: ${seconds} s"
    cargo +nightly fuzz run -O "$t" "$work/$t" -- -max_total_time="$seconds" -max_len=65536 \
        -artifact_prefix="artifacts/$t/" 2>&1 | tee "$logs/$t.log" | grep -E "^#[0-9]+.*(DONE|pulse)|ERROR|panicked|SUMMARY" | tail -3
    echo "   corpus: $(ls "$work/$t" | wc -l) inputs (full log: fuzz/$logs/$t.log)"
done
