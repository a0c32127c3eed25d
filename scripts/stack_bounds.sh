#!/usr/bin/env bash
# Stack bounds of every exported function of the checked-in generated crates on the flight
# controller's ISA (docs/generated-api.md, "Stack"), checked against generated/stack-bounds.json.
#
#   scripts/stack_bounds.sh            measure, print, fail if a bound exceeds its limit (CI)
#   scripts/stack_bounds.sh --update   measure and write the bounds into generated/stack-bounds.json,
#                                      keeping the limits (new entries get bound + 25 %, in 256 B);
#                                      then run scripts/regenerate.sh (headers and READMEs quote them)
#
# Method: thumbv7em-none-eabihf, -C target-cpu=cortex-m7 (FPv5-D16: f64 in hardware), release
# (opt-level 3, LTO, codegen-units 1), rustc nightly with -Z emit-stack-sizes. The Rust API is bounded
# through the firmware example's stack_probe_<crate> binaries (one #[inline(never)] probe per public
# function, runtime/firmware-example/src/lib.rs), the C ABI through the capi staticlibs linked by
# arm-none-eabi-gcc with every ABI function as a root. scripts/stack_bound.py sums frames along the
# call graph of the linked ELF (frames from the prologues and rustc's .stack_sizes, the larger) and
# refuses indirect calls, variable frames and recursion. An interrupt preempting the call adds its own
# frame (up to 104 B of FPU context + the handler's) on top.
set -euo pipefail
cd "$(dirname "$0")/.."
update=0
[ "${1:-}" = --update ] && update=1

# Its own target directory: other RUSTFLAGS than the workspace's builds.
target=$(realpath -m "${CARGO_TARGET_DIR:-target}")/stack-bounds
flags="-Z emit-stack-sizes -C target-cpu=cortex-m7"
toolchain=+nightly
rustup target add --toolchain nightly thumbv7em-none-eabihf >/dev/null 2>&1 || true

echo "== building the probes (nightly, thumbv7em-none-eabihf, cortex-m7, -Z emit-stack-sizes)"
CARGO_TARGET_DIR=$target RUSTFLAGS="$flags" cargo $toolchain build --release -q \
    --target thumbv7em-none-eabihf -p sindy_m100_capi -p sindy_m100_riccati_capi
(cd runtime/firmware-example &&
    CARGO_TARGET_DIR=$target RUSTFLAGS="-C link-arg=-Tlink.x $flags" cargo $toolchain build --release -q \
        --target thumbv7em-none-eabihf --bin stack_probe_sindy_m100 --bin stack_probe_sindy_m100_riccati \
        --bin stack_probe_pd_hover_f32)
out=$target/thumbv7em-none-eabihf/release

rust_fns="new initialize set_guess set_disturbance prepare feedback solve shift planned_inputs predicted_states discrete_dynamics"
c_fns="storage_size storage_align init set_guess prepare feedback solve shift set_disturbance last_status first_input qp_iterations cost planned_inputs predicted_states discrete_dynamics"

results=$(mktemp)
trap 'rm -f "$results"' EXIT
for crate in sindy_m100 sindy_m100_riccati pd_hover_f32; do
    roots=$(for f in $rust_fns; do printf 'stack_probe_%s ' "$f"; done)
    # shellcheck disable=SC2086
    python3 scripts/stack_bound.py --json "$out/stack_probe_$crate" $roots |
        python3 -c 'import json,sys; [print(sys.argv[1], "rust", k.replace("stack_probe_",""), v["bytes"]) for k,v in json.load(sys.stdin).items()]' "$crate" >>"$results"
done
for crate in sindy_m100 sindy_m100_riccati; do
    elf=$target/capi_$crate.elf
    undefined=$(for f in $c_fns; do printf -- '-Wl,-u,%s_%s ' "$crate" "$f"; done)
    # shellcheck disable=SC2086
    arm-none-eabi-gcc -mcpu=cortex-m7 -mthumb -mfloat-abi=hard -mfpu=fpv5-d16 -nostdlib -nostartfiles \
        -Wl,--gc-sections -Wl,-e,${crate}_init $undefined "$out/lib${crate}_capi.a" -lgcc -o "$elf"
    roots=$(for f in $c_fns; do printf '%s_%s ' "$crate" "$f"; done)
    # shellcheck disable=SC2086
    python3 scripts/stack_bound.py --json "$elf" $roots |
        python3 -c 'import json,sys; p=sys.argv[1]+"_"; [print(sys.argv[1], "c", k[len(p):], v["bytes"]) for k,v in json.load(sys.stdin).items()]' "$crate" >>"$results"
done

python3 - "$results" "$update" <<'EOF'
import json, sys
path = "generated/stack-bounds.json"
rows = [l.split() for l in open(sys.argv[1]) if l.strip()]
update = sys.argv[2] == "1"
try:
    table = json.load(open(path))
except FileNotFoundError:
    table = {}
table.setdefault("target", "thumbv7em-none-eabihf, -C target-cpu=cortex-m7, release (opt-level 3, LTO), rustc nightly -Z emit-stack-sizes")
table.setdefault("command", "scripts/stack_bounds.sh")
crates = table.setdefault("crates", {})
over = []
print(f"{'crate':20} {'api':4} {'function':18} {'bound B':>8} {'limit B':>8}")
for crate in sorted({r[0] for r in rows}):
    # What the figures describe: the crate's model and options lines (the generator quotes them only
    # for a crate generated with the same ones).
    head = [l[2:].strip() for l in open(f"generated/{crate}/Cargo.toml") if l.startswith("# model:") or l.startswith("# options:")]
    if update:
        crates.setdefault(crate, {})["generated_with"] = head
    elif crates.get(crate, {}).get("generated_with") != head:
        over.append(f"{crate}: generated with other options than the table's (run scripts/stack_bounds.sh --update)")
for crate, api, fn, b in rows:
    b = int(b)
    entry = crates.setdefault(crate, {}).setdefault(api, {}).setdefault(fn, {})
    limit = entry.get("limit")
    if limit is None:
        limit = max(256, -(-b * 5 // 4 // 256) * 256)
        if update:
            entry["limit"] = limit
    if update:
        entry["bound"] = b
    flag = "" if b <= limit else "  OVER THE LIMIT"
    if b > limit:
        over.append(f"{crate} {api} {fn}: {b} B > {limit} B")
    print(f"{crate:20} {api:4} {fn:18} {b:8} {limit:8}{flag}")
if update:
    with open(path, "w") as f:
        json.dump(table, f, indent=1, sort_keys=True)
        f.write("\n")
    print(f"wrote {path}")
if over:
    print("stack bounds over their limits (generated/stack-bounds.json):\n  " + "\n  ".join(over), file=sys.stderr)
    sys.exit(1)
EOF
