#!/usr/bin/env bash
# Issue 10 items 3 and 4: do persistent threads (Aila and Laine, HPG 2009: `--persistent on`, as
# many workgroups as the GPU holds, subgroups taking pixels from a counter and refilling the lanes
# whose rays ended) make small frames fill the H100? Targets at 1920x1440 on the dragon's medium
# shot: primary rays >= 6 G/s (LST cast was 4.0), AO rays >= 2 G/s (ao8 was 1.45), and 1920x1440
# within 85% of 7680x4320's rays per second (was 58%).
#
#   main    one `trace-vk bench`: 1920x1440 and 7680x4320, cast and ao8, lst and stackless, each
#           with `--persistent off,on` side by side (rows METHOD+plain and METHOD+persistent); run
#           REPEATS times, each table kept, the summary takes the median over the runs
#   sweep   cast at 480x360, 960x720, 1920x1440, 3840x2880 and 7680x4320, lst and stackless, off
#           and on: time per frame, and per variant the least-squares line t = a + b * pixels
#           (a: the fixed cost per frame, its dispatch's ramp-up and tail; b: ns per pixel)
#   refill  1920x1440, cast and ao8, persistent only, `--persistent-refill 1,4,8,16,32` (idle
#           lanes of 32 before a subgroup takes new pixels; 32 is persistent threads without
#           replacement): whether the default of 8 is the right one
#
# What to read (summary.md):
#   table 1: Mrays/s per method, mode, size, plain and persistent (all rays of the frame over its
#            time, as the bench counts), the persistent gain, and small / large for each.
#            Persistent threads win where `on` beats `off`. The last column checks the targets at
#            the small size: cast Mrays/s >= 6000; the AO rays alone (AO rays over the time ao8
#            adds to the cast frame, as docs/gpu-benchmark.md counts them) >= 2000; small/large
#            >= 85%, each with the better of off and on.
#   table 2: the sweep's fit per variant. A fixed cost a that persistent threads shrink is the
#            dispatch tail they remove; an unchanged b with a lower a means the small frame gains
#            only by the tail.
#   table 3: Mrays/s per refill threshold. If 32 is as fast as 8, replacing finished lanes buys
#            nothing here (the gain is the fill alone); if another value wins, make it the default.
# The decision: if `+persistent` is faster at 1920x1440 for a method and mode (both repeats), make
# `--persistent on` the default for it; if it is slower at 7680x4320 by more than the repeats'
# spread, keep it a per-size choice (or off).
#
# Run from the repository root on the H100 machine. Expects release binaries in .bin/:
#   .bin/trace-vk .bin/bvhc        cargo build --release -p tools
# and, where .gl/ holds the Vulkan loader packages of /work/shared/device.md, unpacks them first.
# Writes $OUT (default out/h100-persistent): summary.md (read this), log.txt, main-N.csv/.out,
# sweep.csv/.out, refill-N.csv/.out. About 4 to 5 minutes.
#
# Env: FRAMES (default 30), REPEATS (default 3), METHODS (default lst,stackless), INVOCATIONS
# (--persistent-invocations; default the renderer's); for a trial run on a small machine only:
# SMALL, LARGE, SWEEP (sizes), SCENE_FILE.
set -uo pipefail
SMALL=${SMALL:-1920x1440}
LARGE=${LARGE:-7680x4320}
SWEEP=${SWEEP:-480x360,960x720,1920x1440,3840x2880,7680x4320}
SCENE_FILE=${SCENE_FILE:-scenes/dragon.toml}
OUT=${OUT:-out/h100-persistent}
FRAMES=${FRAMES:-30}
REPEATS=${REPEATS:-3}
METHODS=${METHODS:-lst,stackless}
INVOCATIONS=${INVOCATIONS:-}
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
EXTRA=()
[ -n "$INVOCATIONS" ] && EXTRA=(--persistent-invocations "$INVOCATIONS")

# One bench run: NAME, sizes, modes, frames.
bench() {
  local name=$1 res=$2 modes=$3 frames=$4
  log "$name: $res $modes"
  "$BIN/trace-vk" bench "$SCENE" --cameras medium --res "$res" --modes "$modes" --methods "$METHODS" \
    --persistent off,on --frames "$frames" --csv "$OUT/$name.csv" ${EXTRA[@]+"${EXTRA[@]}"} >"$OUT/$name.out" 2>&1
  local rc=$?
  cat "$OUT/$name.out"
  [ $rc -eq 0 ] || log "$name FAILED (exit $rc)"
}

for i in $(seq 1 "$REPEATS"); do
  bench "main-$i" "$SMALL,$LARGE" cast,ao8 "$FRAMES"
done
bench sweep "$SWEEP" cast 20
# The refill threshold at the small size, persistent kernels only: idle lanes of 32 before a
# subgroup takes new pixels (1: at once; 32: only when all are idle, no replacement).
for refill in 1 4 8 16 32; do
  log "refill-$refill"
  "$BIN/trace-vk" bench "$SCENE" --cameras medium --res "$SMALL" --modes cast,ao8 --methods "$METHODS" \
    --persistent on --persistent-refill "$refill" --frames "$FRAMES" --csv "$OUT/refill-$refill.csv" \
    ${EXTRA[@]+"${EXTRA[@]}"} >"$OUT/refill-$refill.out" 2>&1 || log "refill-$refill FAILED"
done

# Columns of the bench CSV: 4 width, 5 height, 6 mode, 8 method, 9 median_ms, 16 mrays_per_s.
{
  echo "# Persistent threads: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || echo '?')"
  echo
  echo "$SCENE_FILE, medium camera; Mrays/s: median over $REPEATS runs of each run's median of $FRAMES frames (the runs' values in brackets)."
  echo
  echo "| method | mode | size | off Mrays/s | on Mrays/s | on / off | small/large off | small/large on | target |"
  echo "|---|---|---|--:|--:|--:|--:|--:|---|"
  cat "$OUT"/main-*.csv 2>/dev/null | awk -F, -v small_w="${SMALL%x*}" '
    $2 == "triangles" { next }
    {
      m = $8; p = (m ~ /\+persistent$/) ? "on" : "off"; sub(/\+persistent$/, "", m); sub(/\+plain$/, "", m)
      size = ($4 == small_w) ? "small" : "large"
      key = m SUBSEP $6 SUBSEP size SUBSEP p
      n[key]++; v[key, n[key]] = $16; t[key, n[key]] = $9; ao[key] = $14
      list[key] = list[key] (list[key] == "" ? "" : " ") sprintf("%.0f", $16)
      if (!((m SUBSEP $6) in seen)) { seen[m SUBSEP $6] = 1; order[++k] = m SUBSEP $6 }
    }
    function median(arr, key,   i, j, x, a, c) {
      c = n[key]; if (!c) return 0
      for (i = 1; i <= c; i++) a[i] = arr[key, i]
      for (i = 1; i <= c; i++) for (j = i + 1; j <= c; j++) if (a[j] < a[i]) { x = a[i]; a[i] = a[j]; a[j] = x }
      return (c % 2) ? a[(c + 1) / 2] : (a[c / 2] + a[c / 2 + 1]) / 2
    }
    # The AO rays over the time ao8 adds to the cast frame (docs/gpu-benchmark.md counts AO so),
    # in Mrays/s; 0 without a cast row.
    function added(m, mode, size, p,   kc, ka, dt) {
      kc = m SUBSEP "cast" SUBSEP size SUBSEP p; ka = m SUBSEP mode SUBSEP size SUBSEP p
      dt = median(t, ka) - median(t, kc)
      return (n[kc] && dt > 0) ? ao[ka] / dt / 1000 : 0
    }
    END {
      for (i = 1; i <= k; i++) {
        split(order[i], mm, SUBSEP)
        for (s = 1; s <= 2; s++) {
          size = (s == 1) ? "small" : "large"
          base = order[i] SUBSEP size
          off = median(v, base SUBSEP "off"); on = median(v, base SUBSEP "on")
          so = median(v, order[i] SUBSEP "small" SUBSEP "off") / (median(v, order[i] SUBSEP "large" SUBSEP "off") + 1e-9)
          sn = median(v, order[i] SUBSEP "small" SUBSEP "on") / (median(v, order[i] SUBSEP "large" SUBSEP "on") + 1e-9)
          note = ""
          if (mm[2] ~ /^ao/) {
            a0 = added(mm[1], mm[2], size, "off"); a1 = added(mm[1], mm[2], size, "on")
            note = sprintf("AO rays alone %.0f off, %.0f on; ", a0, a1)
          }
          if (size == "small") {
            if (mm[2] == "cast") { goal = 6000; best = (on > off) ? on : off }
            else if (mm[2] ~ /^ao/) { goal = 2000; best = (a1 > a0) ? a1 : a0 }
            else goal = 0
            if (goal) note = note sprintf("%s: %.0f%% of %d; ", (best >= goal) ? "met" : "missed", 100 * best / goal, goal)
            bestratio = (sn > so) ? sn : so
            note = note sprintf("ratio %s", (bestratio >= 0.85) ? "met" : "missed")
          }
          printf "| %s | %s | %s | %.0f [%s] | %.0f [%s] | %.2f | %.0f%% | %.0f%% | %s |\n", mm[1], mm[2], size, \
            off, list[base SUBSEP "off"], on, list[base SUBSEP "on"], (off > 0) ? on / off : 0, 100 * so, 100 * sn, note
        }
      }
    }'
  echo
  echo "Sizes: small $SMALL, large $LARGE."
  echo
  echo "## Frame time against size (cast): t = a + b * pixels, least squares over $SWEEP"
  echo
  echo "| variant | ms per size | a (ms) | b (ns/pixel) |"
  echo "|---|---|--:|--:|"
  [ -f "$OUT/sweep.csv" ] && awk -F, '
    $2 == "triangles" { next }
    {
      m = $8; px = $4 * $5; ms = $9
      if (!(m in seen)) { seen[m] = 1; order[++k] = m }
      c[m]++; sx[m] += px; sy[m] += ms; sxx[m] += px * px; sxy[m] += px * ms
      times[m] = times[m] (times[m] == "" ? "" : ", ") sprintf("%dx%d %.3f", $4, $5, ms)
    }
    END {
      for (i = 1; i <= k; i++) {
        m = order[i]; d = c[m] * sxx[m] - sx[m] * sx[m]
        b = (d != 0) ? (c[m] * sxy[m] - sx[m] * sy[m]) / d : 0
        a = (sy[m] - b * sx[m]) / c[m]
        printf "| %s | %s | %.3f | %.4f |\n", m, times[m], a, b * 1e6
      }
    }' "$OUT/sweep.csv"
  echo
  echo "## Refill threshold at $SMALL (persistent): Mrays/s by idle lanes of 32 before a refill"
  echo
  echo "| method | mode | 1 | 4 | 8 (default) | 16 | 32 (no replacement) |"
  echo "|---|---|--:|--:|--:|--:|--:|"
  for refill in 1 4 8 16 32; do
    [ -f "$OUT/refill-$refill.csv" ] && awk -F, -v r="$refill" '$2 != "triangles" { m = $8; sub(/\+refill[0-9]+$/, "", m); print m "|" $6 "|" r "|" $16 }' "$OUT/refill-$refill.csv"
  done | awk -F'|' '
    { key = $1 " | " $2; v[key, $3] = $4; if (!(key in seen)) { seen[key] = 1; order[++k] = key } }
    END {
      for (i = 1; i <= k; i++) {
        key = order[i]
        printf "| %s | %.0f | %.0f | %.0f | %.0f | %.0f |\n", key, v[key, 1], v[key, 4], v[key, 8], v[key, 16], v[key, 32]
      }
    }'
} >"$OUT/summary.md"
cat "$OUT/summary.md"
log "done"
