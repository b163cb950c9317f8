#!/usr/bin/env bash
# Issue 16 item 3 (made for the H100 machine): what the default edge-consistent triangle test costs
# against Möller-Trumbore, the only difference between the runs being `trace-vk bench --intersect`
# (same binary, same kernels otherwise). Runs A (watertight), B (mt), A, B ... alternating, so drift
# of the shared machine shows as a difference between the A runs. Also, where .bin/ holds the test
# binary, the full workgroup-shape test of issue 15 (WORKGROUP_SHAPES_ALL=1: every shape, SST up
# to 1024 invocations). About 6 minutes.
#
# Run from the repository root. Expects in .bin/: trace-vk, bvhc (cargo build --release -p tools),
# optionally workgroup-shapes-tests (the binary `cargo test --release -p tests --test
# workgroup_shapes --no-run` names). The tests find scenes through the path they were built in:
# set BUILD_ROOT to that checkout's root (default /work/main) and it is linked to this one.
# Writes $OUT (default out/h100-edge-ab): bench-*.csv/.md, shapes.txt, log.txt.
#
# Env: RES (default 1280x960), CAMERAS (default medium), MODES (default cast,whitted1), METHODS
# (default lst,stackless,sst), FRAMES (default 20), ROUNDS (default 2: A B A B).
set -euo pipefail
OUT=${OUT:-out/h100-edge-ab}
RES=${RES:-1280x960}
CAMERAS=${CAMERAS:-medium}
MODES=${MODES:-cast,whitted1}
METHODS=${METHODS:-lst,stackless,sst}
FRAMES=${FRAMES:-20}
ROUNDS=${ROUNDS:-2}
BIN=.bin
WORK=$(mktemp -d)
mkdir -p "$OUT" "$WORK/scenes"
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*" | tee -a "$OUT/log.txt" >&2; }
for b in trace-vk bvhc; do [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)" >&2; exit 1; }; done
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  # The test binaries require the validation layer; it goes on their command line only.
  if [ -d .gl/tools ]; then mkdir -p /tmp/vt; for f in .gl/tools/*.deb; do dpkg -x "$f" /tmp/vt; done; fi
fi
"$BIN/trace-vk" devices 2>&1 | tee -a "$OUT/log.txt"
SCENES=()
for t in scenes/*.toml; do
  n=$(basename "$t" .toml)
  "$BIN/bvhc" compile "$t" -o "$WORK/scenes/$n.bvh" >>"$OUT/log.txt" 2>&1
  SCENES+=("$WORK/scenes/$n.bvh")
done
log "compiled ${#SCENES[@]} scenes"
for r in $(seq 1 "$ROUNDS"); do
  for t in watertight mt; do
    log "round $r: --intersect $t"
    "$BIN/trace-vk" bench "${SCENES[@]}" --res "$RES" --cameras "$CAMERAS" --modes "$MODES" --methods "$METHODS" \
      --frames "$FRAMES" --intersect "$t" --csv "$OUT/bench-$r-$t.csv" >>"$OUT/log.txt" 2>&1 || log "bench failed"
  done
done
if [ -x "$BIN/workgroup-shapes-tests" ]; then
  root=${BUILD_ROOT:-/work/main}
  if [ ! -e "$root" ]; then mkdir -p "$(dirname "$root")"; ln -s "$PWD" "$root"; fi
  log "workgroup shapes, every shape"
  WORKGROUP_SHAPES_ALL=1 LD_LIBRARY_PATH=/tmp/vt/usr/lib/x86_64-linux-gnu \
    VK_LAYER_PATH=/tmp/vt/usr/share/vulkan/explicit_layer.d timeout 400 "$BIN/workgroup-shapes-tests" --nocapture --test-threads 1 >"$OUT/shapes.txt" 2>&1 \
    || log "workgroup shapes failed or timed out (exit $?)"
  tail -5 "$OUT/shapes.txt" | tee -a "$OUT/log.txt"
fi
log done
