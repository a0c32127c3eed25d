#!/usr/bin/env python3
"""Worst-case stack bound of functions in a linked Thumb-2 ELF (Cortex-M), from its call graph.

    scripts/stack_bound.py ELF ROOT...    prints "ROOT BYTES" per root (JSON with --json)

Each function's frame is read from its prologue in the disassembly (arm-none-eabi-objdump -d or
llvm-objdump -d): `push`/`stmdb sp!` (4 bytes a register), `str.w rX, [sp, #-N]!`, `vpush` (4 or
8 bytes a register), `sub sp, #N` / `sub.w sp, sp, #N` / `subw sp, sp, #N`. Where the ELF carries
rustc's `.stack_sizes` section (`-Z emit-stack-sizes`, read with llvm-readobj --stack-sizes), the
larger of the two figures is used, and a disagreement is reported on stderr. Calls are `bl`/`blx
<label>` and tail calls (`b`/`b.w <other function>`); a function's bound is its frame plus the
largest bound of its callees. The bound is refused (exit 1) when it cannot be computed: an indirect
call (`blx rN`, `bx rN` other than `bx lr`, a `pc` load other than a `pop`), a stack pointer set
from a register (a variable-size frame, except restoring it from r7/fp in an epilogue), or recursion.
Exceptions and interrupts that preempt a function add their own frames (8 words, 26 with the FPU
context, plus the handler's): this is the bound of the call itself.
"""
import json
import re
import subprocess
import sys

OBJDUMP = ["arm-none-eabi-objdump", "-d", "--no-show-raw-insn"]

FUNC = re.compile(r"^([0-9a-f]+) <(.+)>:$")
INSN = re.compile(r"^\s*([0-9a-f]+):\s+(\S+)\s*(.*)$")


def reg_count(regs: str) -> int:
    """Registers in a list like {r4, r5, r6, r7, lr} or {d8-d15}."""
    n = 0
    for part in regs.strip("{} ").split(","):
        part = part.strip()
        if "-" in part:
            a, b = part.split("-")
            n += int(b[1:]) - int(a[1:]) + 1
        elif part:
            n += 1
    return n


def parse(elf: str):
    out = subprocess.run(OBJDUMP + [elf], check=True, capture_output=True, text=True).stdout
    funcs = {}
    addr_name = {}
    cur = None
    for line in out.splitlines():
        m = FUNC.match(line)
        if m:
            cur = m.group(2)
            addr_name[int(m.group(1), 16)] = cur
            funcs[cur] = {"frame": 0, "calls": set(), "problems": [], "insns": []}
            continue
        m = INSN.match(line)
        if m and cur is not None:
            funcs[cur]["insns"].append((int(m.group(1), 16), m.group(2), m.group(3)))
    for name, f in funcs.items():
        frame = 0
        for _, op, args in f["insns"]:
            args = args.split(";")[0].split("@")[0].strip()
            base = op.split(".")[0]
            if base in ("push", "stmdb") and (base == "push" or args.startswith("sp!")):
                frame += 4 * reg_count(args[args.index("{"):])
            elif base == "vpush":
                size = 8 if "d" in args else 4
                frame += size * reg_count(args)
            elif base == "str" and re.match(r"\w+, \[sp, #-(\d+)\]!", args):
                frame += int(re.match(r"\w+, \[sp, #-(\d+)\]!", args).group(1))
            elif base in ("sub", "subw") and re.match(r"sp, (sp, )?#(\d+)", args):
                frame += int(re.match(r"sp, (sp, )?#(\d+)", args).group(2))
            elif base in ("sub", "subw", "mov", "add") and re.match(r"sp, ", args):
                # sp set from a register: an epilogue restoring it (from r7/fp) is fine, anything
                # else is a variable-size frame.
                if not re.match(r"sp, (r7|fp|r11)(, #\d+)?$", args) and not re.match(r"sp, (sp, )?#\d+$", args):
                    f["problems"].append(f"sp set by `{op} {args}`")
            if base in ("bl", "blx", "b", "cbz", "cbnz") or re.match(r"b(eq|ne|cs|cc|hs|lo|mi|pl|vs|vc|hi|ls|ge|lt|gt|le)$", base):
                t = re.search(r"<([^>+]+)(\+0x[0-9a-f]+)?>", args)
                if t:
                    target = t.group(1)
                    if target != name and t.group(2) is None and base in ("bl", "blx", "b"):
                        f["calls"].add(target)
                    elif target != name and base in ("bl", "blx"):
                        f["calls"].add(target)
                elif base in ("blx",):
                    f["problems"].append(f"indirect call `{op} {args}`")
            if base == "bx" and args != "lr":
                f["problems"].append(f"indirect branch `{op} {args}`")
            if base in ("ldr", "mov") and args.startswith("pc"):
                f["problems"].append(f"pc set by `{op} {args}`")
        f["frame"] = frame
    return funcs


def rustc_sizes(elf: str):
    """Frame sizes from .stack_sizes (rustc -Z emit-stack-sizes), if the ELF has them."""
    try:
        out = subprocess.run(["llvm-readobj", "--stack-sizes", elf], capture_output=True, text=True).stdout
    except FileNotFoundError:
        return {}
    sizes = {}
    names = []
    for line in out.splitlines():
        m = re.search(r"Functions: \[(.*)\]", line)
        if m:
            names = [n.strip() for n in m.group(1).split(",")]
        m = re.search(r"Size: (0x[0-9A-Fa-f]+)", line)
        if m:
            for n in names:
                sizes[n] = int(m.group(1), 16)
    return sizes


def bound(funcs, root, memo, stack, path):
    if root in memo:
        return memo[root]
    if root not in funcs:
        raise ValueError(f"{root}: not in the ELF (called from {' -> '.join(stack)})")
    if root in stack:
        raise ValueError(f"recursion: {' -> '.join(stack + [root])}")
    f = funcs[root]
    if f["problems"]:
        raise ValueError(f"{root}: {'; '.join(f['problems'])} (called from {' -> '.join(stack)})")
    best, best_path = 0, []
    for c in sorted(f["calls"]):
        b, p = bound(funcs, c, memo, stack + [root], path)
        if b > best:
            best, best_path = b, p
    memo[root] = (f["frame"] + best, [root] + best_path)
    return memo[root]


def main(argv):
    as_json = "--json" in argv
    argv = [a for a in argv if a != "--json"]
    if len(argv) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    elf, roots = argv[0], argv[1:]
    funcs = parse(elf)
    for name, size in rustc_sizes(elf).items():
        if name in funcs and size != funcs[name]["frame"]:
            print(f"note: {name}: prologue {funcs[name]['frame']} B, .stack_sizes {size} B (the larger is used)", file=sys.stderr)
            funcs[name]["frame"] = max(size, funcs[name]["frame"])
    memo = {}
    result = {}
    status = 0
    for r in roots:
        try:
            b, p = bound(funcs, r, memo, [], [])
            result[r] = {"bytes": b, "path": p}
        except ValueError as e:
            print(f"error: {e}", file=sys.stderr)
            status = 1
    if as_json:
        print(json.dumps(result, indent=1))
    else:
        for r, v in result.items():
            print(f"{r} {v['bytes']}  ({' > '.join(v['path'][:6])})")
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
