#!/usr/bin/env bash
# The firmware example's closed loop on emulated Cortex-M cores (QEMU system emulation, MPS2 boards):
# per-step instruction counts on the target ISA, the stack high-water mark, flash and RAM from the ELF.
#
#   scripts/target_bench.sh          all four runs (f32 and f64, on the M4 and on the M7) and the table
#   scripts/target_bench.sh --ci     the three runs CI makes (not f64 on the M4: soft-float, ~30 s)
#
# Each run: runtime/firmware-example built with `--features qemu` (memory/mps2.x, semihosting, painted
# stack) for -C target-cpu=cortex-m4 (mps2-an386) or cortex-m7 (mps2-an500, double-precision FPU),
# then `qemu-system-arm -icount shift=0` runs UAVGEN_TARGET_SECONDS (build time, default 10) of
# simulated flight on the circle with two 1 m reference jumps, the model as the aircraft. The binary
# calibrates its SysTick-based instruction counter against a loop of known length, and exits non-zero
# on any feedback or reference error; so does this script. See docs/benchmarks.md "On the target".
set -euo pipefail
cd "$(dirname "$0")/.."

ci=0
case "${1:-}" in
    --ci) ci=1 ;;
    "") ;;
    *) echo "usage: $0 [--ci]" >&2; exit 2 ;;
esac

if ! command -v qemu-system-arm >/dev/null; then
    echo "qemu-system-arm not found (Debian: apt-get install qemu-system-arm)" >&2
    exit 1
fi
size_tool=$(command -v llvm-size || command -v arm-none-eabi-size || true)
nm_tool=$(command -v llvm-nm || command -v arm-none-eabi-nm || true)

fw=runtime/firmware-example
build() { # $1 = cpu (cortex-m4 | cortex-m7)
    # Its own target directory per CPU (the RUSTFLAGS differ), whatever CARGO_TARGET_DIR says.
    (cd "$fw" && RUSTFLAGS="-C link-arg=-Tlink.x -C target-cpu=$1" \
        cargo build --release -q --features qemu --bins --target-dir "target/qemu-$1")
}
echo "building the QEMU firmware (cortex-m4, cortex-m7)" >&2
build cortex-m4
build cortex-m7

runs=("an386 cortex-m4 qemu_pd_hover_f32" "an500 cortex-m7 qemu_pd_hover_f32" "an500 cortex-m7 qemu_sindy_m100")
[ "$ci" = 1 ] || runs+=("an386 cortex-m4 qemu_sindy_m100")

rows=()
status=0
for run in "${runs[@]}"; do
    read -r board cpu bin <<<"$run"
    elf=$fw/target/qemu-$cpu/thumbv7em-none-eabihf/release/$bin
    echo "== $bin on mps2-$board ($cpu)" >&2
    set +e
    out=$(timeout 300 qemu-system-arm -M "mps2-$board" -nographic -monitor none -serial none \
        -icount shift=0 -semihosting-config enable=on,target=native -kernel "$elf" 2>&1)
    rc=$?
    set -e
    echo "$out" >&2
    if [ "$rc" != 0 ]; then
        echo "$bin on mps2-$board: exit status $rc (124: timed out)" >&2
        status=1
        continue
    fi
    result=$(grep '^RESULT ' <<<"$out" || true)
    if [ -z "$result" ]; then
        echo "$bin on mps2-$board: no RESULT line" >&2
        status=1
        continue
    fi
    field() { sed -n "s/.* $1=\([^ ]*\).*/\1/p" <<<"$result"; }
    flash=- ram=-
    if [ -n "$size_tool" ]; then
        # Flash: what is loaded (vector table, code, constants, .data's initialiser). RAM: .data and
        # .bss without the benchmark's own per-step record (the STEPS static); the stack comes on top.
        read -r flash ram < <("$size_tool" -A "$elf" | awk '
            $1 == ".vector_table" || $1 == ".text" || $1 == ".rodata" { f += $2 }
            $1 == ".data" { f += $2; r += $2 }
            $1 == ".bss" || $1 == ".uninit" { r += $2 }
            END { print f, r }')
        if [ -n "$nm_tool" ]; then
            steps=$("$nm_tool" -S --demangle "$elf" | awk '$4 ~ /::STEPS(::h[0-9a-f]+)?$/ && !s { s = $2 } END { print s }')
            ram=$((ram - 16#${steps:-0}))
        fi
    fi
    prec=f32
    [ "$bin" = qemu_sindy_m100 ] && prec=f64
    rows+=("$(field steps) ${bin#qemu_} $prec $board $cpu $(field step_median) $(field step_max) \
$(field feedback_max) $(field prepare_max) $(field stack_bytes) $flash $ram")
done

echo
echo "Per control step (feedback + prepare_next), instructions executed (QEMU -icount), over $(cut -d' ' -f1 <<<"${rows[0]:-0}") steps:"
echo
echo "| crate | real | board (core) | median | max | feedback max | prepare max | stack B | flash B | RAM B | max ms @480 MHz | max ms @168 MHz |"
echo "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|--:|"
for row in "${rows[@]}"; do
    read -r _ crate prec board cpu med max fbmax prmax stack flash ram <<<"$row"
    core=M4; [ "$cpu" = cortex-m7 ] && core=M7
    ms480=$(awk -v n="$max" 'BEGIN { printf "%.2f", n / 480e3 }')
    ms168=$(awk -v n="$max" 'BEGIN { printf "%.2f", n / 168e3 }')
    # 480 MHz is an H7 (M7), 168 MHz an F4 (M4): quote each for the core it belongs to.
    if [ "$core" = M7 ]; then ms168=-; else ms480=-; fi
    echo "| $crate | $prec | mps2-$board ($core) | $med | $max | $fbmax | $prmax | $stack | $flash | $ram | $ms480 | $ms168 |"
done
echo
echo "ms = instructions / clock at one instruction per cycle; the control period at 30 Hz is 33.3 ms."
exit "$status"
