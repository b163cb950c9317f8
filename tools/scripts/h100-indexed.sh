#!/usr/bin/env bash
# Issue 8 leftovers, item 1 (made for the H100 machine): both tracers' vertex forms side by side,
# `--vertices expanded` (48 bytes per triangle, three reads) against `--vertices indexed` (the
# file's form read through the index: trace-vk uploads 16 bytes per triangle and 16 per vertex,
# trace-cpu drops its 48-byte copy and reads the file's arrays in place). `trace-vk bench` of the
# dragon and million at 1920x1440 (medium camera; cast and whitted1; LST, stackless and SST; both
# forms in one run, ROUNDS runs), the bytes each uploads, one chart of memory beside speed, and
# whether the two forms' images are the same bit for bit; then the CPU tracer's forms on the
# 16-core host (tracer-cpu's vertex_forms example: both forms' frames interleaved, packet, ordered,
# bvh8 and auto, cast and whitted). About 4 minutes (each step has its own time limit; the whole
# stays under 6).
#
# Run from the repository root. Expects in .bin/: trace-vk, trace-cpu, bvhc (cargo build
# --release -p tools), vertices_chart (cargo build --release -p tools --example vertices_chart)
# and vertex_forms (cargo build --release -p tracer-cpu --example vertex_forms).
# Writes $OUT (default out/h100-indexed): summary.md (read this), round*.csv/.md, chart.svg,
# cpu.md, log.txt.
#
# What summary.md prints, in order:
# - "Bytes uploaded (bvhc info)": per scene the line `bytes/triangle file F; trace-cpu holds E,
#   with --vertices indexed I ...; trace-vk uploads ...` (dragon: trace-vk 87.2 -> 63.2, trace-cpu
#   144.3 -> 96.3 bytes per triangle);
# - "Round N": per scene, mode and method the indexed form's bytes uploaded per triangle and median
#   ms per frame over the expanded form's (columns "memory" and "time"; under 1 is less);
# - "Images": every scene x method must say "same";
# - "CPU (16 threads)": per scene, mode and method the bytes per triangle trace-cpu holds in each
#   form, Mrays/s of each (median of interleaved frames) and indexed/expanded (above 1: indexed is
#   faster), and "same" in the images column.
# What decides the defaults: trace-vk's stays expanded unless indexed is faster (time < 1) for LST
# (its default method) on both scenes and both modes in both rounds; trace-cpu's stays expanded
# unless indexed is at least 0.98 as fast for auto (its default method) in all four scene x mode
# rows (memory for no speed). Any "DIFFER" is a bug, whatever the times.
# ROUNDS=0 skips the GPU timing (run once already: docs/gpu-benchmark.md, "On the H100"), leaving
# the bytes, the images and the CPU section (about 2 minutes).
#
# Env: RES (default 1920x1440), METHODS (default lst,stackless,sst), FRAMES (default 50), ROUNDS
# (default 2). Run on the H100 on 2026-11-25 (docs/gpu-benchmark.md, "Vertex forms"): the default stays expanded.
set -euo pipefail
OUT=${OUT:-out/h100-indexed}
RES=${RES:-1920x1440}
METHODS=${METHODS:-lst,stackless,sst}
FRAMES=${FRAMES:-50}
ROUNDS=${ROUNDS:-2}
BIN=.bin
WORK=$(mktemp -d)
mkdir -p "$OUT" "$WORK/scenes" "$WORK/img"
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*" | tee -a "$OUT/log.txt" >&2; }
for b in trace-vk trace-cpu bvhc vertices_chart vertex_forms; do [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)" >&2; exit 1; }; done
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
"$BIN/trace-vk" devices 2>&1 | tee -a "$OUT/log.txt"
for s in dragon million; do
  log "bvhc compile scenes/$s.toml"
  timeout 60 "$BIN/bvhc" compile "scenes/$s.toml" -o "$WORK/scenes/$s.bvh" >>"$OUT/log.txt" 2>&1
  "$BIN/bvhc" info "$WORK/scenes/$s.bvh" | grep 'bytes/triangle' | sed "s/^ */$s: /" | tee -a "$OUT/log.txt"
done
SCENES=("$WORK/scenes/dragon.bvh" "$WORK/scenes/million.bvh")
for r in $(seq "$ROUNDS"); do
  log "trace-vk bench round $r"
  timeout 90 "$BIN/trace-vk" bench "${SCENES[@]}" --cameras medium --res "$RES" --modes cast,whitted1 \
    --methods "$METHODS" --vertices expanded,indexed --frames "$FRAMES" --csv "$OUT/round$r.csv" \
    2>&1 | tee -a "$OUT/log.txt" | grep 'uploads' || log "bench round $r failed (see log.txt)"
done
{
  echo "# --vertices expanded and indexed: trace-vk on $("$BIN/trace-vk" devices 2>/dev/null | head -1 | cut -d'(' -f1 | sed 's/^[0-9]*: //')"
  echo
  echo "- Date: $(date -u '+%Y-%m-%d %H:%M UTC'); host $(hostname), $(nproc) cores; script tools/scripts/h100-indexed.sh; git $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
  echo "- trace-vk bench, medium camera, $RES, median of $FRAMES frames; both forms of a method timed one after the other in each run"
  echo
  echo "## Bytes uploaded (bvhc info)"
  echo
  grep 'bytes/triangle' "$OUT/log.txt" | sed 's/^/- /'
  for r in $(seq "$ROUNDS"); do
    [ -f "$OUT/round$r.csv" ] || continue
    echo
    echo "## Round $r"
    echo
    "$BIN/vertices_chart" "$OUT/round$r.csv" "${SCENES[@]}" -o "$OUT/chart$r.svg" 2>>"$OUT/log.txt"
  done
  echo
  echo "## Images, 640x480 whitted: expanded against indexed"
  echo
  echo "| scene | method | images |"
  echo "|---|---|---|"
  for s in dragon million; do
    for m in ${METHODS//,/ }; do
      for v in expanded indexed; do
        timeout 20 "$BIN/trace-vk" render "$WORK/scenes/$s.bvh" --res 640x480 --method "$m" --vertices "$v" \
          -o "$WORK/img/$s-$m-$v.png" >>"$OUT/log.txt" 2>&1 || true
      done
      # The PNGs byte for byte (tests/tests/cross_backend.rs compares the AOVs' bits too; the
      # EXR files themselves differ between two runs of one setting).
      if [ -s "$WORK/img/$s-$m-expanded.png" ] && cmp -s "$WORK/img/$s-$m-expanded.png" "$WORK/img/$s-$m-indexed.png"; then
        echo "| $s | $m | same |"
      else
        echo "| $s | $m | DIFFER (or a render failed: see log.txt) |"
      fi
    done
  done
  echo
  echo "## CPU ($(nproc) threads): trace-cpu's forms, medium camera, $RES, frames interleaved"
  echo
  log "vertex_forms (CPU)"
  timeout 90 "$BIN/vertex_forms" "${SCENES[@]}" --size "$RES" --methods packet,ordered,bvh8,auto --reps 5 --seconds 1.5 \
    2>>"$OUT/log.txt" | tee "$OUT/cpu.md" || echo "(the CPU measurement failed or ran out of time: see log.txt)"
  echo
  echo "- $(($(date +%s) - START)) s in all"
} >"$OUT/summary.md"
[ -f "$OUT/chart1.svg" ] && cp "$OUT/chart1.svg" "$OUT/chart.svg"
rm -rf "$WORK"
log "done: $OUT/summary.md"
cat "$OUT/summary.md"
