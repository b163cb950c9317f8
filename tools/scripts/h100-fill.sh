#!/usr/bin/env bash
# Issue 10 item 3, second half: do small frames fill the GPU? A 1920x1440 frame of the bare dragon
# reached 58% (LST cast) of the rays per second of a 7680x4320 frame
# (docs/measurements/h100-2026-11-23-sizes); the target is 85%. This runs, side by side in one
# run, 1920x1440 against 7680x4320 for each variant:
#   base      one frame per submission (today's `trace-vk bench`)
#   flight4   `--in-flight 4`: four frames recorded back to back into each submission, waited for
#             once, timed as their mean (no gaps between submissions: host work, fence waits)
#   flight16  `--in-flight 16`
#   tiles     `--tile-pixels 2764800`: the 7680x4320 frame cut into 12 dispatches of 1920x1440's
#             pixel count (bands of 7680x360), so its rays keep the large frame's coherence with
#             the small frame's dispatch size
#   base43    `base` against 7680x5760: 1920x1440's 4:3 aspect at 4x the size. 7680x4320 is 16:9,
#             a wider view with more cheap background rays: on the dragon's medium camera its
#             rays take 18% less traversal work each (tools/examples/warp_cost: 12.2 against
#             14.9 nodes and triangles per ray; 7680x5760: 14.9)
#   base2     `base` again at the end: how far the machine drifted during the run
# and samples the GPU's SM clock (nvidia-smi, every 100 ms) during each variant.
#
# What to read (summary.md): the "small / large" column per variant. If flight4/flight16 bring
# it near 85%, the gaps between submissions (and the clocks they let drop) are the cause and
# several frames in flight are the remedy. If `tiles` keeps the large frame's rate while the
# small frame stays low in every variant, a dispatch of 1920x1440 fills the GPU and the gap is
# the small frame's less coherent rays (an 8x8 workgroup spans 4x the angle of the large frame's),
# which no scheduling recovers. The SM clock column shows whether a variant ran at lower clocks.
# Expected from the work alone (tools/examples/warp_cost on the dragon, medium camera: the largest
# lane's work per 32-lane warp, 19.0 at 1920x1440, 13.7 at 7680x4320, 16.6 at 7680x5760): a
# 1920x1440 frame that filled the GPU perfectly would reach about 72% of 7680x4320's rate and 87%
# of 7680x5760's (LST cast, caches aside); what base falls short of that is fill, clocks or cache.
#
# Run from the repository root on the H100 machine. Expects release binaries in .bin/:
#   .bin/trace-vk .bin/bvhc        cargo build --release -p tools
# and, where .gl/ holds the Vulkan loader packages of /work/shared/device.md, unpacks them first.
# Writes $OUT (default out/h100-fill): summary.md (read this), log.txt, one CSV and Markdown table
# per variant, clocks-VARIANT.csv. About 5 minutes.
#
# Env: FRAMES (default 20), METHODS (default lst,stackless), MODES (default cast,whitted1); for a
# trial run on a small machine only: SMALL, LARGE (sizes), SCENE_FILE.
set -uo pipefail
SMALL=${SMALL:-1920x1440}
LARGE=${LARGE:-7680x4320}
LARGE43=${LARGE43:-7680x5760}
SCENE_FILE=${SCENE_FILE:-scenes/dragon.toml}
TILE=$((${SMALL%x*} * ${SMALL#*x}))
OUT=${OUT:-out/h100-fill}
FRAMES=${FRAMES:-20}
METHODS=${METHODS:-lst,stackless}
MODES=${MODES:-cast,whitted1}
BIN=.bin
mkdir -p "$OUT"
: >"$OUT/log.txt"
exec > >(tee -a "$OUT/log.txt") 2>&1
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*"; }

for b in trace-vk bvhc; do
  [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)"; exit 1; }
done
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
nvidia-smi -L || true
"$BIN/trace-vk" devices
echo "git: $(git rev-parse --short HEAD 2>/dev/null || echo '?'); date: $(date -u '+%Y-%m-%d %H:%M UTC')"

SCENE=$(mktemp -d)/scene.bvh
"$BIN/bvhc" compile "$SCENE_FILE" -o "$SCENE" --quiet || exit 1

# One variant: the bench with extra options, with the SM clock sampled meanwhile.
variant() {
  local name=$1
  shift
  log "variant $name: $*"
  local sampler=""
  if command -v nvidia-smi >/dev/null; then
    nvidia-smi --query-gpu=clocks.sm,utilization.gpu --format=csv,noheader,nounits -lms 100 \
      >"$OUT/clocks-$name.csv" 2>/dev/null &
    sampler=$!
  fi
  "$BIN/trace-vk" bench "$SCENE" --cameras medium --res "$SMALL,${LARGE_NOW:-$LARGE}" --modes "$MODES" \
    --methods "$METHODS" --frames "$FRAMES" --csv "$OUT/$name.csv" "$@" >"$OUT/$name.out" 2>&1
  local rc=$?
  [ -n "$sampler" ] && kill "$sampler" 2>/dev/null && wait "$sampler" 2>/dev/null
  cat "$OUT/$name.out"
  [ $rc -eq 0 ] || log "variant $name FAILED (exit $rc)"
}

variant base
variant flight4 --in-flight 4
variant flight16 --in-flight 16
variant tiles --tile-pixels "$TILE"
LARGE_NOW=$LARGE43 variant base43
variant base2

# summary.md: per variant, method and mode the two rates and their ratio, and the SM clock.
{
  echo "# Small frames against large ones: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || echo '?')"
  echo
  echo "$SCENE_FILE, medium camera, median of $FRAMES frames per setting; Mrays/s from each variant's bench CSV."
  echo
  echo "| variant | method | mode | $SMALL Mrays/s | $LARGE Mrays/s | small / large | SM MHz median (min) |"
  echo "|---|---|---|--:|--:|--:|--:|"
  for name in base flight4 flight16 tiles base43 base2; do
    csv="$OUT/$name.csv"
    [ -f "$csv" ] || { echo "| $name | (failed) | | | | | |"; continue; }
    clock="?"
    if [ -s "$OUT/clocks-$name.csv" ]; then
      clock=$(cut -d, -f1 "$OUT/clocks-$name.csv" | sort -n | awk '{a[NR]=$1} END {if (NR) printf "%d (%d)", a[int((NR+1)/2)], a[1]}')
    fi
    # Columns: 4 width, 6 mode, 8 method, 16 mrays_per_s.
    awk -F, -v name="$name" -v clock="$clock" -v small_w="${SMALL%x*}" 'NR > 1 {
        key = $8 " | " $6
        if ($4 == small_w) small[key] = $16; else large[key] = $16
        if (!(key in seen)) { seen[key] = 1; order[++n] = key }
      }
      END {
        for (i = 1; i <= n; i++) {
          k = order[i]
          ratio = (large[k] > 0) ? sprintf("%.0f%%", 100 * small[k] / large[k]) : "?"
          printf "| %s | %s | %.0f | %.0f | %s | %s |\n", name, k, small[k], large[k], ratio, clock
        }
      }' "$csv"
  done
  echo
  echo "In \`tiles\` the $LARGE frame ran in dispatches of at most $TILE pixels (its $SMALL row is the base frame)."
  echo "In \`base43\` the large frame is $LARGE43 (the small frame's aspect), elsewhere $LARGE."
} >"$OUT/summary.md"
cat "$OUT/summary.md"
log "done"
