#!/usr/bin/env python3
"""Self instructions of a callgrind profile, by the source line of one function they were
inlined into.

callgrind_annotate credits an inlined helper's instructions to the helper's own file (or to
`core::slice::index`), not to the line of the kernel that called it. This maps every
instruction address through its chain of inlined frames (`addr2line -i`) and credits it to the
line of the outermost frame whose name holds FUNCTION (and, given INNER, to the line of the
outermost frame inside it whose name holds INNER).

    valgrind --tool=callgrind --dump-instr=yes --callgrind-out-file=cg.out \\
        --toggle-collect='*plan_motion*' BINARY bench mbm ...
    benches/profile/inlined_lines.py cg.out BINARY free_lanes_in [pose_lanes] [--top 60]

`--event Bcm` credits the conditional branches callgrind's simulator mispredicted instead
(record with `--branch-sim=yes`).

BINARY must be built with line tables (`CARGO_PROFILE_RELEASE_DEBUG=line-tables-only`).
"""
import argparse
import collections
import re
import subprocess
import sys


def self_costs(path, event):
    """Counts of `event` per address, excluding the inclusive costs of call lines."""
    cost = collections.Counter()
    addr = line = 0
    after_call = False
    index = None

    def value(tok, prev):
        if tok == "*":
            return prev
        if tok[0] in "+-":
            return prev + int(tok, 0)
        return int(tok, 0)

    try:
        f = open(path)
    except OSError as e:
        sys.exit(f"{path}: cannot read the profile ({e.strerror})")
    with f:
        for raw in f:
            text = raw.strip()
            if not text:
                continue
            if text[0].isdigit() or text[0] in "+-*":
                if index is None:
                    sys.exit(f"{path}: costs before the events line: not a callgrind profile")
                parts = text.split()
                addr = value(parts[0], addr)
                if len(parts) > 2:
                    line = value(parts[1], line)
                if after_call:
                    after_call = False
                elif len(parts) >= 3 and index < len(parts) - 2:
                    # Trailing zero counts may be left out of a line.
                    cost[addr] += int(parts[2 + index])
            elif text.startswith("events:"):
                names = text.split()[1:]
                if event not in names:
                    sys.exit(f"{path}: no event {event} recorded (it has {' '.join(names)})")
                index = names.index(event)
            elif text.startswith("calls="):
                after_call = True
            elif re.match(r"^positions:", text) and "instr" not in text:
                sys.exit(f"{path}: recorded without --dump-instr=yes")
    return cost


def frames(binary, addrs):
    """Inlined frames (function, file:line), innermost first, per address."""
    try:
        done = subprocess.run(
            ["addr2line", "-i", "-f", "-C", "-a", "-e", binary],
            input="\n".join(hex(a) for a in addrs),
            capture_output=True,
            text=True,
        )
    except OSError as e:
        sys.exit(f"addr2line: cannot run it ({e.strerror}); it comes with binutils")
    if done.returncode != 0:
        sys.exit(f"{binary}: addr2line failed: {done.stderr.strip()}")
    out = done.stdout.split("\n")
    result, cur, i = {}, None, 0
    while i < len(out):
        if out[i].startswith("0x"):
            cur = int(out[i], 16)
            result[cur] = []
            i += 1
        elif not out[i]:
            i += 1
        else:
            loc = out[i + 1] if i + 1 < len(out) else ""
            result[cur].append((out[i], loc.rsplit("/", 1)[-1]))
            i += 2
    return result


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("profile")
    p.add_argument("binary")
    p.add_argument("function")
    p.add_argument("inner", nargs="?")
    p.add_argument("--top", type=int, default=60)
    p.add_argument(
        "--event",
        default="Ir",
        help="the count to credit (Ir: instructions; with --branch-sim=yes, Bcm: conditional branches mispredicted)",
    )
    a = p.parse_args()
    cost = self_costs(a.profile, a.event)
    lines = collections.Counter()
    total = 0
    for addr, chain in frames(a.binary, sorted(cost)).items():
        outer = [k for k, (fn, _) in enumerate(chain) if a.function in fn]
        if not outer:
            continue
        k = outer[-1]
        total += cost[addr]
        key = chain[k][1]
        if a.inner:
            inner = [j for j, (fn, _) in enumerate(chain[:k]) if a.inner in fn]
            if not inner:
                continue
            key = chain[inner[-1]][1]
        lines[key] += cost[addr]
    print(f"{total:>12}  in {a.function} (of {sum(cost.values())} collected)")
    for key, c in lines.most_common(a.top):
        print(f"{c:>12}  {key}")


if __name__ == "__main__":
    main()
