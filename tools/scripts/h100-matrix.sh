#!/usr/bin/env bash
# Issue 10 item 6 (made for the H100 machine): the whole GPU matrix of docs/gpu-benchmark.md. Every
# shipped scene, its medium shot at 1920x1440, modes cast, whitted1, ao8, diffuse, every method the
# device offers, in one `trace-vk bench` run (so that every ratio is side by side), then the chart of
# rays per second per method and kind of ray (bench_chart --ray-types: a mode's extra rays over the
# time it adds to the cast frame). About 5 minutes on the H100.
#
# Run from the repository root. Expects in .bin/: trace-vk, bvhc, bench_chart (cargo build --release
# -p tools --examples), and lib/ + fonts/ with fonts.sh for the chart (plotters needs fontconfig).
# Writes $OUT (default out/h100-matrix): matrix.csv and its Markdown copy matrix.md, rays-by-type.{svg,png},
# modes.{svg,png}, log.txt.
#
# Env: RES (default 1920x1440), METHODS (default: every method `trace-vk devices` reports for the
# device), MODES (default cast,whitted1,ao8,diffuse), FRAMES (default 10).
set -uo pipefail
OUT=${OUT:-out/h100-matrix}
RES=${RES:-1920x1440}
MODES=${MODES:-cast,whitted1,ao8,diffuse}
FRAMES=${FRAMES:-10}
BIN=.bin
WORK=$(mktemp -d)
mkdir -p "$OUT" "$WORK/scenes"
: >"$OUT/log.txt"
exec > >(tee -a "$OUT/log.txt") 2>&1
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*"; }
for b in trace-vk bvhc; do [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)"; exit 1; }; done
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
"$BIN/trace-vk" devices
if [ -z "${METHODS:-}" ]; then
  METHODS=lst,stackless,sst,sst-subgroup
  "$BIN/trace-vk" devices 2>&1 | grep -q "rt-pipeline: supported" && METHODS=$METHODS,rt-pipeline
  "$BIN/trace-vk" render --help 2>&1 | grep -q cwbvh && METHODS=$METHODS,cwbvh
fi
log "methods $METHODS, modes $MODES, $RES"
SCENES=()
for t in scenes/*.toml; do
  n=$(basename "$t" .toml)
  # --layout all: the wide layout too, for cwbvh (and auto among the methods).
  if "$BIN/bvhc" compile "$t" --layout all -o "$WORK/scenes/$n.bvh" >>"$WORK/bvhc.txt" 2>&1; then
    SCENES+=("$WORK/scenes/$n.bvh")
  else
    log "bvhc failed on $t"; tail -3 "$WORK/bvhc.txt"
  fi
done
log "compiled ${#SCENES[@]} scenes"
"$BIN/trace-vk" bench "${SCENES[@]}" --res "$RES" --cameras medium --modes "$MODES" --methods "$METHODS" \
  --frames "$FRAMES" --csv "$OUT/matrix.csv" || log "bench failed"
log "bench done"
if [ -x "$BIN/bench_chart" ]; then
  [ -f "$BIN/fonts.sh" ] && . "$BIN/fonts.sh"
  for ext in svg png; do
    "$BIN/bench_chart" "$OUT/matrix.csv" --ray-types -o "$OUT/rays-by-type.$ext" || log "chart failed"
    "$BIN/bench_chart" "$OUT/matrix.csv" -o "$OUT/modes.$ext" || log "chart failed"
  done
fi
log "done"
