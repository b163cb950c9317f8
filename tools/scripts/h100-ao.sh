#!/usr/bin/env bash
# Issue 10 item 2 and the AO target of item 4 (made for the H100 machine): incoherent rays on the
# GPU. The dragon's medium shot at 1920x1440 with ray casting (the coherent baseline), ambient
# occlusion (8 rays per hit of 10% of the scene's bounding-box diagonal: the issue's target of 2
# billion AO rays per second) and the diffuse bounce, on LST, SST and stackless; then the same
# modes on every shipped scene, and one image of each mode per method to look at. About 5 minutes.
#
# Run from the repository root. Expects in .bin/: trace-vk, bvhc (cargo build --release -p tools).
# Writes $OUT (default out/h100-ao): dragon-*.csv/.md (one per round), scenes.csv/.md, images/,
# summary.txt, log.txt.
#
# What to read (summary.txt): per method, the bench's Mrays/s of the ao8 row counts every ray of
# the frame (primary + AO) over the whole frame's GPU time; "AO only" divides the AO rays by the
# frame time minus the median time of the cast row of the same method (the primary rays and their
# shading), an estimate of the AO pass alone. The target is AO only >= 2000 Mrays/s on the fastest
# method. The diffuse row likewise (one bounce per hit, closest hit, full length). The ratio of the
# ao8 rate to the cast rate says how much incoherence costs each method.
#
# Env: RES (default 1920x1440), METHODS (default lst,sst,stackless), FRAMES (default 30), ROUNDS
# (default 2: the dragon twice, to see drift).
set -euo pipefail
OUT=${OUT:-out/h100-ao}
RES=${RES:-1920x1440}
METHODS=${METHODS:-lst,sst,stackless}
FRAMES=${FRAMES:-30}
ROUNDS=${ROUNDS:-2}
MODES=cast,ao8,diffuse
BIN=.bin
WORK=$(mktemp -d)
mkdir -p "$OUT/images" "$WORK/scenes"
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*" | tee -a "$OUT/log.txt" >&2; }
for b in trace-vk bvhc; do [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)" >&2; exit 1; }; done
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
"$BIN/trace-vk" devices 2>&1 | tee -a "$OUT/log.txt"
SCENES=()
for t in scenes/*.toml; do
  n=$(basename "$t" .toml)
  "$BIN/bvhc" compile "$t" -o "$WORK/scenes/$n.bvh" >>"$OUT/log.txt" 2>&1
  SCENES+=("$WORK/scenes/$n.bvh")
done
log "compiled ${#SCENES[@]} scenes"
DRAGON="$WORK/scenes/dragon.bvh"

for r in $(seq 1 "$ROUNDS"); do
  log "round $r: dragon medium $RES, $MODES"
  "$BIN/trace-vk" bench "$DRAGON" --res "$RES" --cameras medium --modes "$MODES" --methods "$METHODS" \
    --frames "$FRAMES" --csv "$OUT/dragon-$r.csv" >>"$OUT/log.txt" 2>&1 || log "bench failed"
done
log "every shipped scene, medium $RES, $MODES"
"$BIN/trace-vk" bench "${SCENES[@]}" --res "$RES" --cameras medium --modes "$MODES" --methods "$METHODS" \
  --frames 10 --csv "$OUT/scenes.csv" >>"$OUT/log.txt" 2>&1 || log "bench failed"

log "images (dragon medium, 960x720)"
for m in ${METHODS//,/ }; do
  for mode in ao diffuse; do
    "$BIN/trace-vk" render "$DRAGON" --camera medium --res 960x720 --mode "$mode" --method "$m" \
      -o "$OUT/images/dragon-$mode-$m.png" >>"$OUT/log.txt" 2>&1 || log "render $mode $m failed"
  done
done

# Columns of the CSV: 1 scene, 6 mode, 8 method, 9 median_ms, 11 primary, 14 ao, 15 diffuse, 16 Mrays/s.
{
  echo "AO and diffuse rays on the H100 ($RES, medium camera; Mrays/s = million rays per second)"
  for f in "$OUT"/dragon-*.csv "$OUT/scenes.csv"; do
    [ -f "$f" ] || continue
    echo "== $(basename "$f")"
    awk -F, 'NR > 1 { key = $1 " " $8; ms[key, $6] = $9; rays[key, $6] = $14 + $15; all[key, $6] = $16; keys[key] = 1 }
      END {
        for (k in keys) {
          c = ms[k, "cast"];
          split("ao8 diffuse", list, " ");
          for (i = 1; i <= 2; i++) {
            mode = list[i];
            if (!((k, mode) in ms)) continue;
            only = (ms[k, mode] > c && c > 0) ? rays[k, mode] / (ms[k, mode] - c) / 1e3 : 0;
            printf "%-28s %-8s frame %8.3f ms (cast %7.3f ms)  all rays %8.1f Mrays/s  %s only %8.1f Mrays/s  (cast %8.1f)\n",
              k, mode, ms[k, mode], c, all[k, mode], mode, only, all[k, "cast"];
          }
        }
      }' "$f" | sort
  done
} | tee "$OUT/summary.txt"
log done
