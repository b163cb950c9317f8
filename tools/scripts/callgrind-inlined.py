#!/usr/bin/env python3
"""Instructions of a callgrind profile by the inlined function they came from.

The traversals are inlined whole into one entry (`packet8::avx2::trace`, `bvh8::avx2::trace`), so
callgrind_annotate gives them one line, or lines of the intrinsics' wrappers. This reads the
per-instruction counts of a profile made with `--dump-instr=yes`, asks addr2line for each
instruction's inline chain, and charges the instruction to the innermost function of the chain
that is the tracer's own and not a one-line helper (the vector wrappers `add`, `mul`, `load`...),
so the frustum test, the leaf test and the walk's bookkeeping each get their share.

Usage: callgrind-inlined.py PROFILE BINARY [PER] [--lines FUNCTION]
  PROFILE   a callgrind.out made with --dump-instr=yes (e.g. with --toggle-collect='*packet8*trace*'),
            or the histogram tools/stepcount writes (the AVX-512 path valgrind cannot run; only the
            main executable's addresses are read)
  BINARY    the binary it profiled, with its debug info (the release profile keeps line tables)
  PER       divide the counts by this (packets or rays traced), to print instructions per item
  --lines F instead, the source lines of function F (a suffix of its path, e.g. avx2::walk)
Needs binutils' addr2line. Made for stop 43 (docs/measurements/vm-2026-11-27-stop43); stepcount's
histograms since stop 44 (docs/measurements/vm-2026-11-28-stop44).
"""
import collections
import re
import subprocess
import sys

# Helpers that are one vector operation or a load: their instructions go to their caller.
HELPER = re.compile(
    r"::(add|sub|mul|div|splat|load|store|store_i|dist|fmadd|fmsub|imax|cmp|and|or|bits|mask_of|any|count"
    r"|zero|dot|cross|keep|ptr|lines_ptr|node|block|bounded|node_unchecked|block_unchecked)$"
    r"|\{\{closure\}\}|counters::add|Lanes<.*>::new"
)
ADDRESS = re.compile(r"^(0x[0-9a-f]+|[+-]\d+|\*)$")
LINE = re.compile(r"^(\d+|[+-]\d+|\*)$")


def counts_by_address(path):
    """Instruction address -> Ir, from a profile whose positions are `instr line`, or -> steps,
    from a stepcount histogram (`address count` lines; other modules' addresses are left out)."""
    counts = collections.Counter()
    with open(path) as f:
        if f.readline().startswith("# stepcount"):
            for text in f:
                if not text.startswith("#"):
                    addr, n = text.split()
                    if int(addr, 16) < 1 << 32:
                        counts[int(addr, 16)] += int(n)
            return counts
    addr = line = 0
    after_call = False

    def step(token, old):
        if token == "*":
            return old
        if token.startswith(("+", "-")):
            return old + int(token)
        return int(token, 16) if token.startswith("0x") else int(token)

    for text in open(path):
        if text.startswith("calls="):
            after_call = True  # the next cost line is the call's inclusive cost, not this code's
            continue
        parts = text.split()
        if len(parts) == 3 and ADDRESS.match(parts[0]) and LINE.match(parts[1]):
            addr, line = step(parts[0], addr), step(parts[1], line)
            if after_call:
                after_call = False
                continue
            counts[addr] += int(parts[2])
        else:
            after_call = False
    return counts


def inline_chains(binary, addresses):
    """Address -> [(function, file:line)], innermost first."""
    out = subprocess.run(
        ["addr2line", "-a", "-i", "-f", "-C", "-e", binary] + [hex(a) for a in addresses],
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split("\n")
    chains, current, i = {}, None, 0
    while i < len(out):
        if out[i].startswith("0x"):
            current = int(out[i], 16)
            chains[current] = []
            i += 1
        elif out[i] == "":
            i += 1
        else:
            chains[current].append((out[i], out[i + 1] if i + 1 < len(out) else ""))
            i += 2
    return chains


def owner(chain):
    """The frame an instruction is charged to: the innermost own, non-helper function."""
    own = [(f, loc) for f, loc in chain if f.startswith("tracer_cpu::")]
    for f, loc in own:
        if not HELPER.search(f):
            return f, loc
    return own[-1] if own else (None, "")


def main():
    args = sys.argv[1:]
    lines_of = None
    if "--lines" in args:
        k = args.index("--lines")
        lines_of = args[k + 1]
        del args[k : k + 2]
    profile, binary = args[0], args[1]
    per = float(args[2]) if len(args) > 2 else None
    counts = counts_by_address(profile)
    chains = inline_chains(binary, sorted(counts))
    total = sum(counts.values())
    agg = collections.Counter()
    for a, n in counts.items():
        f, loc = owner(chains.get(a, []))
        if lines_of is None:
            agg[f] += n
        elif f and f.endswith(lines_of):
            agg[loc.split("/src/")[-1].split(" ")[0]] += n
    print(f"total {total} instructions" + (f", {total / per:.1f} per item" if per else ""))
    for key, n in agg.most_common(60):
        share = f"{n / per:8.1f} per item" if per else ""
        print(f"{100 * n / total:6.2f}% {n:>13} {share} {key}")


if __name__ == "__main__":
    main()
