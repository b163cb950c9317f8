#!/usr/bin/env bash
# Instructions per ray of our single-ray walk against Embree's, on the same rays in one process:
# callgrind (valgrind) collects only inside the AVX2 walk (`bvh8::avx2::trace` and what it calls)
# and inside `rtcOccluded1`/`rtcIntersect1`. Deterministic where timings on a shared machine are
# not, so a change to the walk's code can be judged here before the H100 host times it; but an
# instruction is not a cycle (stop 31: 4% fewer instructions moved no 16-thread row there).
# Valgrind hides AVX-512, so Embree runs its AVX2 kernels under it.
#
# Usage, from the repository root: bash tools/scripts/callgrind-rays.sh KIND [SCENE] (default
# bunny; scenes/SCENE.toml), with the ray report
# built: cargo build --release -p tracer-cpu --features embree --example ray_report
# (BIN overrides the binary). Needs valgrind (apt-get install -y valgrind). Prints ours, Embree's
# and their ratio; leaves the profile in $OUT (default /tmp/callgrind-rays) for callgrind_annotate.
set -euo pipefail
KIND=${1:?name a ray kind: primary, shadow, secondary, ao or diffuse}
SCENE=${2:-bunny}
BIN=${BIN:-target/release/examples/ray_report}
OUT=${OUT:-/tmp/callgrind-rays}
mkdir -p "$OUT"
f="$OUT/$SCENE-$KIND"
valgrind --tool=callgrind --collect-atstart=no --toggle-collect='*bvh8::avx2::trace*' \
  --toggle-collect=rtcOccluded1 --toggle-collect=rtcIntersect1 --callgrind-out-file="$f.out" \
  "$BIN" --scene "$SCENE=scenes/$SCENE.toml" --sizes 320x240 --threads 1 --reps 1 --kinds "$KIND" \
  --engines "ours bvh8" --out "$f.md" >"$f.log" 2>&1
# Both tracers trace the same rays the same number of times (their passes alternate), so the
# ratio of the totals is the ratio per ray.
callgrind_annotate --inclusive=yes "$f.out" >"$f.inclusive" 2>/dev/null
total=$(awk '/PROGRAM TOTALS/ { gsub(",", "", $1); print $1; exit }' "$f.inclusive")
embree=$(awk '/rtcOccluded1|rtcIntersect1/ { gsub(",", "", $1); print $1; exit }' "$f.inclusive")
ours=$((total - embree))
echo "$SCENE $KIND: ours $ours instructions, Embree $embree, ours / Embree $(awk -v a="$ours" -v b="$embree" 'BEGIN { printf "%.3f", a / b }')"
