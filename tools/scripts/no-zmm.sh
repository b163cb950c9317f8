#!/usr/bin/env bash
# Fails when the CPU tracer's walks in BINARY (default: the release trace-cpu) use a 512-bit
# register. Their AVX-512 paths are compiled for AVX-512's 32 registers and mask compares on
# 256-bit vectors only; where such a function zeroes or copies 64 bytes or more, LLVM does it with
# one 512-bit move instead, and without the three it did so in the wide packets the 16-thread
# primary packets ran 1-4 points faster against Embree on the H200 machine's Xeon host
# (docs/cpu-benchmark-log.md, stop 56). Needs objdump (binutils).
set -euo pipefail
bin=${1:-${CARGO_TARGET_DIR:-target}/release/trace-cpu}
[ -f "$bin" ] || { echo "error: $bin does not exist; build it first (cargo build --release --bin trace-cpu)" >&2; exit 1; }
command -v objdump >/dev/null || { echo "error: objdump is missing; install binutils" >&2; exit 1; }
# Functions of the wide BVH's single-ray walk (bvh8) and of the wide packets (packet8), by their
# mangled names, and the ones among them with a zmm operand.
report=$(objdump -d --no-show-raw-insn "$bin" | awk '
  /^[0-9a-f]+ <.*>:$/ { f = $2; if (f ~ /tracer_cpu(4bvh8|7packet8)/) walks++ }
  /zmm/ && f ~ /tracer_cpu(4bvh8|7packet8)/ { z[f]++ }
  END { print walks + 0; for (k in z) print z[k] " in " k }')
walks=$(head -1 <<<"$report")
if [ "$walks" = 0 ]; then
  echo "error: $bin holds no function of tracer_cpu::bvh8 or tracer_cpu::packet8 to check" >&2
  exit 1
fi
if [ "$(wc -l <<<"$report")" -gt 1 ]; then
  echo "error: the CPU tracer's walks in $bin use 512-bit registers (zmm operands, per function):" >&2
  tail -n +2 <<<"$report" >&2
  exit 1
fi
echo "no 512-bit register in the $walks functions of the CPU tracer's wide walks ($bin)"
