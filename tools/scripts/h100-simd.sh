#!/usr/bin/env bash
# Issue 11 items 1 and 2 (branch simd11) on the H100 machine's 16-core host: the ray report (ours
# beside Embree 3, the same rays on the same triangles) on bunny, dragon and million at 1920x1440,
# 1 and all threads, primary, shadow, secondary, AO and diffuse rays. New columns against
# h100-cpuwide.sh: "ours bvh8 AVX-512" (the wide BVH's single-ray traversal with the AVX-512 path
# forced; "ours bvh8" is the AVX2 path, the default) and "ours bvh8 packet" (`--method
# bvh8-packet`: 8-ray AVX2 packets on the wide BVH, Embree's coherent walk since branch pkt8),
# beside rtcIntersect1/rtcOccluded1 and rtcIntersect8/rtcOccluded8 (default and robust flags).
# Since branch bvh4 also "ours bvh4" (`--method bvh4`: the 4-wide BVH, 4 children per node,
# 128-bit node and leaf tests, one ray at a time): the first table's last three columns
# `bvh4 / Embree 1`, `bvh4 / Embree 1 robust` and `bvh4 / bvh8`.
# ENGINES="ours bvh4,ours bvh8,Embree 1,Embree 1 robust" runs only those tracers (`--engines`;
# about 2 minutes instead of 6), e.g. with SIZES=640x480,1920x1440; ENGINES="ours bvh8 packet,
# ours packet,Embree 8,Embree 8 robust" only the packet target's.
#
# Run from the repository root on the device machine. The host has no Rust toolchain nor Embree:
# build here (Debian 12 with libembree-dev) and carry .bin/ (ignored):
#   cargo build --release -p tracer-cpu --features embree --example ray_report
#   mkdir -p .bin && cp target/release/examples/ray_report .bin/ && strip .bin/ray_report
#   (cd /tmp && apt-get download libembree3-3 libtbb12 libtbbmalloc2) && for d in /tmp/lib*.deb; do dpkg -x "$d" .bin/embree; done
# (.bin/embree/usr/lib/x86_64-linux-gnu then holds libembree3.so.3 and libtbb.so.12; a caller that
# sets LD_LIBRARY_PATH to its own copy may leave .bin/embree out.) The scenes are the tracked
# files under scenes/.
# Device tool: command `bash tools/scripts/h100-simd.sh`, carry [".bin"]. Writes into $OUT
# (default ./out/h100-simd): ray-report.md (the report's markdown: issue 11's ratios first, then
# Mrays/s and hit agreement; written at the end), host.txt, log.txt (one line per measured row
# as it goes: Mrays/s of the 12 tracers in the report's column order, `-` for one left out, so a
# cut-off run still tells; the 3rd is bvh8, the 5th bvh8 packet, the 6th and 7th Embree 1 and
# robust, the 8th and 9th Embree 8 and robust, the 12th bvh4), and at the end of stdout the packet
# target's rows: primary and shadow, bvh8 packet / Embree 8 and / Embree 8 robust (issue 11 item 2:
# >= 100%), packet (binary tree) / Embree 8.
# Expected run time at 1920x1440: about 4 minutes for seven tracers at REPS=5, about 6 for all 12
# at REPS=3 (the one-thread passes over the dragon's and million's sets are most of it).
# SIZES=640x480,1920x1440 adds the small size (about 2 more minutes).
set -euo pipefail
OUT=${OUT:-out/h100-simd}
SIZES=${SIZES:-1920x1440}
ENGINES=${ENGINES:-}
# REPS: rounds per row (5 by default). A thread of this KVM guest is sometimes slowed for seconds:
# the 16-thread rows hold to 2-3 points, but the one-thread rows of a run with seven tracers still
# moved by up to 40 points at 5 (2026-11-27); for one thread, run two tracers with
# tools/scripts/h100-ray-ab.sh (THREADS=1), which read within a few points (docs/cpu-benchmark.md).
REPS=${REPS:-5}
mkdir -p "$OUT"
[ -x .bin/ray_report ] || { echo "missing .bin/ray_report (see the top of $0)" >&2; exit 1; }
if [ -d .bin/embree/usr/lib/x86_64-linux-gnu ]; then
  export LD_LIBRARY_PATH=$PWD/.bin/embree/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
if ldd .bin/ray_report | grep -q 'not found'; then
  echo "ray_report cannot find its libraries (Embree 3 and TBB; see the top of $0):" >&2
  ldd .bin/ray_report | grep 'not found' >&2
  exit 1
fi
ALL=$(nproc)
{
  echo "host: $ALL cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "flags: $(grep -m1 '^flags' /proc/cpuinfo | tr ' ' '\n' | grep -E '^(avx2|fma|avx512f|avx512vl|avx512dq)$' | tr '\n' ' ')"
  echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
  # Whether the wide BVH's madvise for huge pages (branch sr11) can change anything here: with
  # `[always]` its arrays had them before too, with `[madvise]` only since.
  echo "transparent huge pages: $(cat /sys/kernel/mm/transparent_hugepage/enabled 2>/dev/null || echo '?')"
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC'); git: $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
} | tee "$OUT/host.txt"
exec > >(tee "$OUT/log.txt") 2>&1

echo "== ray report: bunny, dragon, million; $SIZES; 1 and $ALL threads =="
.bin/ray_report --sizes "$SIZES" --threads "1,$ALL" --reps "$REPS" ${ENGINES:+--engines "$ENGINES"} \
  --out "$OUT/ray-report.md" >/dev/null
echo "done: $OUT/ray-report.md"
echo "== packets against Embree 8, primary and shadow rays (target >= 100% in both Embree columns) =="
echo "scene | size | kind | threads | bvh8 packet / Embree 8 | bvh8 packet / Embree 8 robust | packet / Embree 8"
# Columns of the report's first table: 2-5 the row, 9-11 the three packet ratios.
awk -F'|' '/^### Throughput/ { exit } $4 ~ /^ (primary|shadow) $/ { print $2 "|" $3 "|" $4 "|" $5 "|" $9 "|" $10 "|" $11 }' "$OUT/ray-report.md"
