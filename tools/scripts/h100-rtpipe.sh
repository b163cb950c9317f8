#!/usr/bin/env bash
# Issue 10 item 1, `--method rt-pipeline` on an NVIDIA GPU (made for the H100 machine): does the
# vendor's traversal give LST's images (primary-hit triangle ids equal but for ties, pixels), what
# does the driver's acceleration-structure build take beside bvhc's, and how fast is it in
# `trace-vk bench` beside LST. About 5 to 10 minutes.
#
# Run from the repository root. Expects release binaries in .bin/ (built on the development
# machine: they link only libc, libm and libgcc_s):
#   .bin/trace-vk .bin/bvhc                    cargo build --release -p tools
#   .bin/image_diff .bin/aov_diff              cargo build --release -p tools --example image_diff
#                                              --example aov_diff
#   .bin/rt-pipeline-tests (optional)          the binary `cargo test --release -p tests --test
#                                              rt_pipeline --no-run` names (target/release/deps/rt_pipeline-*)
# and, where .gl/ holds the Vulkan loader packages of /work/shared/device.md, unpacks them first.
# Scenes: scenes/*.toml (and the meshes they name), compiled here with bvhc.
# Writes $OUT (default out/h100-rtpipe): summary.md (read this), log.txt (everything, also echoed),
# bench.tgz (CSV and Markdown tables) and differing.tgz (image pairs that differ).
#
# Env: RES (default 1280x960), MODES (default "cast whitted"), BENCH_RES (default 1920x1440),
# FRAMES (default 20), BENCH_MODES (default cast,whitted1,whitted2), SCENE_FILES (default
# scenes/*.toml).
set -uo pipefail
set -x
OUT=${OUT:-out/h100-rtpipe}
RES=${RES:-1280x960}
MODES=${MODES:-cast whitted}
BENCH_RES=${BENCH_RES:-1920x1440}
FRAMES=${FRAMES:-20}
BENCH_MODES=${BENCH_MODES:-cast,whitted1,whitted2}
BIN=.bin
WORK=$(mktemp -d)
mkdir -p "$OUT" "$WORK/scenes" "$WORK/img" "$WORK/differing" "$WORK/bench"
: >"$OUT/log.txt"
exec > >(tee -a "$OUT/log.txt") 2>&1
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*"; }

for b in trace-vk bvhc image_diff aov_diff; do
  [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)"; exit 1; }
done
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  # The validation layer, used on the command lines of with_layer only.
  if [ -d .gl/tools ]; then mkdir -p /tmp/vt; for f in .gl/tools/*.deb; do dpkg -x "$f" /tmp/vt; done; fi
fi
with_layer() {
  if [ -d /tmp/vt ]; then
    env LD_LIBRARY_PATH=/tmp/vt/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH} \
      VK_LAYER_PATH=/tmp/vt/usr/share/vulkan/explicit_layer.d "$@"
  else
    "$@"
  fi
}
nvidia-smi || true
echo "VK_DRIVER_FILES=${VK_DRIVER_FILES:-} LD_LIBRARY_PATH=${LD_LIBRARY_PATH:-}"
"$BIN/trace-vk" devices

# Every shipped scene, compiled once; bvhc's build time kept for the table.
SCENES=()
declare -A BVHC_BUILD
for t in ${SCENE_FILES:-scenes/*.toml}; do
  n=$(basename "$t" .toml)
  if "$BIN/bvhc" compile "$t" -o "$WORK/scenes/$n.bvh" >"$WORK/bvhc-$n.txt" 2>&1; then
    cat "$WORK/bvhc-$n.txt"
    BVHC_BUILD[$n]=$(grep -o 'build [0-9.]* s' "$WORK/bvhc-$n.txt" | head -1 | cut -d' ' -f2)
    SCENES+=("$n")
  else
    cat "$WORK/bvhc-$n.txt"
    log "bvhc failed on $t"
  fi
done

# 1. One small render under the validation layer first, so that a failure says why.
log "validation-layer smoke test"
SMOKE=ok
for mode in cast whitted; do
  if ! with_layer "$BIN/trace-vk" render "$WORK/scenes/room.bvh" --method rt-pipeline --validate --mode "$mode" \
    --res 64x48 -o "$WORK/img/smoke-$mode.png"; then
    SMOKE="FAILED ($mode)"
  fi
done
log "smoke: $SMOKE"

{
  echo "# rt-pipeline on $("$BIN/trace-vk" devices 2>/dev/null | head -1 | cut -d'(' -f1 | sed 's/^[0-9]*: //')"
  echo
  echo "- Date: $(date -u '+%Y-%m-%d %H:%M UTC'); host $(hostname), $(nproc) cores; script tools/scripts/h100-rtpipe.sh; git $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
  echo "- Devices: $("$BIN/trace-vk" devices 2>&1 | tr '\n' ' ')"
  echo "- Validation-layer smoke test (room, 64x48, cast and whitted, --validate): $SMOKE"
  echo
} >"$OUT/summary.md"

# 2. The device tests: rt-pipeline against LST with the cross-backend tolerance (the ignored
# tests need a device with ray tracing), and the refusal/acceptance test.
if [ -x "$BIN/rt-pipeline-tests" ]; then
  log "rt-pipeline-tests"
  export SCENES_DIR="$PWD/scenes"
  with_layer "$BIN/rt-pipeline-tests" --include-ignored --nocapture --test-threads 1 \
    >"$WORK/tests.txt" 2>&1
  rc=$?
  cat "$WORK/tests.txt"
  {
    echo "## tests/tests/rt_pipeline.rs on this device (--include-ignored, validation layer on): exit $rc"
    echo
    echo '```'
    # Each panic with the line after it (the assertion's message).
    sed -n '/panicked/{N;p;d}; /rt-pipeline against LST\|^test \|test result\|built on\|refused on/p' "$WORK/tests.txt" |
      cut -c1-400 | head -60
    echo '```'
    echo
  } >>"$OUT/summary.md"
fi

# 3. Every scene's first camera, LST and rt-pipeline: pixels and primary-hit triangles.
{
  echo "## rt-pipeline against LST, $RES, each scene's first camera"
  echo
  echo "Pixels whose 8-bit colour differs (of $(( ${RES%x*} * ${RES#*x} ))), max channel difference in 1/255 steps; primary hits: same triangle / another at the same distance (tie) / another. Build: bvhc's whole SAH build (CPU) beside the driver's bottom + top level (GPU timestamps). Traversal: the driver's trace passes alone, of the rt-pipeline frame's GPU time (one frame, first render: not a benchmark)."
  echo
  echo "| scene | mode | pixels differing (max) | hits same / ties / other | bvhc build | driver build (bottom + top) | rt traversal / rt frame / LST frame |"
  echo "|---|---|---:|---|---:|---|---|"
} >>"$OUT/summary.md"
total_diff=0
total_other=0
for s in "${SCENES[@]}"; do
  for mode in $MODES; do
    base="$WORK/img/$s-$mode"
    ok=1
    for m in lst rt-pipeline; do
      if ! "$BIN/trace-vk" render "$WORK/scenes/$s.bvh" --mode "$mode" --res "$RES" --method "$m" \
        -o "$base-$m.png" --aov "$base-$m.exr" >"$base-$m.txt" 2>&1; then
        ok=0
      fi
      cat "$base-$m.txt"
    done
    if [ $ok = 0 ]; then
      echo "| $s | $mode | failed (log.txt) | | ${BVHC_BUILD[$s]:-?} s | | |" >>"$OUT/summary.md"
      continue
    fi
    read -r _ _ _ diff _ max < <("$BIN/image_diff" "$base-lst.png" "$base-rt-pipeline.png")
    read -r _ same _ ties _ other < <("$BIN/aov_diff" "$base-lst.exr" "$base-rt-pipeline.exr")
    total_diff=$((total_diff + diff))
    total_other=$((total_other + other))
    [ "$diff" = 0 ] || cp "$base-lst.png" "$base-rt-pipeline.png" "$WORK/differing/"
    build=$(grep -o 'built its structures in [^)]*)' "$base-rt-pipeline.txt" | sed 's/built its structures in //')
    trav=$(grep -o 'its traversal took .*' "$base-rt-pipeline.txt" | sed "s/its traversal took //; s/ of the frame's / \/ /")
    lst_frame=$(grep -o 'on [^:]*: [^,]* GPU' "$base-lst.txt" | sed 's/.*: //; s/ GPU//')
    echo "| $s | $mode | $diff ($max) | $same / $ties / $other | ${BVHC_BUILD[$s]:-?} s | $build | $trav / $lst_frame |" >>"$OUT/summary.md"
  done
done
{
  echo
  echo "**In all: $total_diff pixels differ; $total_other primary hits differ other than by ties.**"
  echo
} >>"$OUT/summary.md"

# 4. trace-vk bench, LST and rt-pipeline side by side in one run (frame time: every pass, the
# rt-pipeline's ray halves and hit halves included).
BENCH_SCENES=()
for s in "${SCENES[@]}"; do BENCH_SCENES+=("$WORK/scenes/$s.bvh"); done
log "trace-vk bench"
timeout 360 "$BIN/trace-vk" bench "${BENCH_SCENES[@]}" --cameras medium --res "$BENCH_RES" --modes "$BENCH_MODES" \
  --methods lst,rt-pipeline --frames "$FRAMES" --csv "$WORK/bench/rtpipe.csv"
log "bench exit $?"
{
  echo "## trace-vk bench, medium camera, $BENCH_RES, median of $FRAMES frames, LST and rt-pipeline in one run"
  echo
  cat "$WORK/bench/rtpipe.md" 2>/dev/null || echo "(the bench failed: see log.txt)"
  echo
  echo "- $(($(date +%s) - START)) s in all"
} >>"$OUT/summary.md"

tar czf "$OUT/bench.tgz" -C "$WORK" bench
if [ -n "$(ls -A "$WORK/differing")" ]; then tar czf "$OUT/differing.tgz" -C "$WORK" differing; fi
rm -rf "$WORK"
log "done: $OUT/summary.md"
cat "$OUT/summary.md"
