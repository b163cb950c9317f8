#!/usr/bin/env bash
# Issue 10, persistent threads per stage (`--persistent auto`, the default of `trace-vk render` and
# `bench`): persistent kernels in the AO and diffuse stages (refill at 16 idle lanes of 32), plain
# kernels for primary, shadow and mirror rays. Measured so far on the H100 (dragon, 1920x1440):
# persistent / plain 0.84-0.89 for LST cast, 0.75-0.85 stackless cast, 1.13-1.34 for ao8, refill
# 16 beating 8 by 4-5% for AO; diffuse and Whitted frames never measured. And the one cell where
# our fastest method lost to the driver's rt-pipeline: the forest's diffuse bounce (0.98).
#
#   One `trace-vk bench` run: scenes dragon and forest, medium camera, $RES, modes cast, whitted1,
#   ao8, diffuse; methods lst, stackless, rt-pipeline; `--persistent off,on,auto
#   --persistent-refill 8,16`. Rows: METHOD+plain (off), METHOD+persistent+refillN (on: every
#   tracing stage), METHOD+refillN (auto: AO and diffuse stages persistent; METHOD+refill16 is
#   exactly the new default, the bare METHOD of a bench without --persistent-refill), rt-pipeline
#   (plain: the driver's traversal has no persistent form; its `+persistent` row says so).
#
# What to read (summary.md):
#   table 1: Mrays/s of the whole frame per scene, mode and method (all rays of the frame over its
#            median time, as the bench counts them) for plain, on 8, on 16, auto 8, auto 16, and
#            the ratios on8/plain, on16/plain and auto16/plain. For cast and whitted1 auto runs the
#            plain kernels, so auto/plain there is the noise of the run (expect 0.98-1.02). The
#            questions: does whitted1 gain with `on` (then its shade/bounce stages may belong to
#            auto too; `on` also makes the primary stage persistent, which loses, so a whitted1
#            on/plain above 1 means the secondary stages gain more than that); does diffuse gain
#            like ao8 (auto16/plain > 1); is 16 still better than 8 for diffuse.
#   table 2: ours against the driver per scene and kind of ray, as docs/gpu-benchmark.md's matrix
#            counts them (cast: the frame; the other modes: the rays they add to the same method's
#            cast frame over the time they add). Columns: the best of our plain kernels, the best
#            of our default (auto 16), the best of any of our variants, rt-pipeline, and the three
#            ratios to rt-pipeline. The forest's diffuse cell was 0.98 with plain kernels: the
#            target is default/rt >= 1 in every row.
#
# Run from the repository root on the H100 machine. Expects release binaries in .bin/:
#   .bin/trace-vk .bin/bvhc        cargo build --release -p tools
# and, where .gl/ holds the Vulkan loader packages of /work/shared/device.md, unpacks them first.
# Writes $OUT (default out/h100-persistent-modes): summary.md (read this), log.txt, bench.csv and
# bench.md. About 3 to 5 minutes (88 settings, 1.5 to 2 s each as in h100-matrix.sh and
# h100-persistent.sh, plus compiling the forest).
#
# Env: FRAMES (default 20), RES (default 1920x1440), SCENE_NAMES (default "dragon forest"; the
# scenes/NAME.toml files), MODES (default cast,whitted1,ao8,diffuse), REFILLS (default 8,16).
set -uo pipefail
OUT=${OUT:-out/h100-persistent-modes}
RES=${RES:-1920x1440}
FRAMES=${FRAMES:-20}
SCENE_NAMES=${SCENE_NAMES:-dragon forest}
MODES=${MODES:-cast,whitted1,ao8,diffuse}
REFILLS=${REFILLS:-8,16}
BIN=.bin
WORK=$(mktemp -d)
mkdir -p "$OUT" "$WORK/scenes"
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

METHODS=lst,stackless
"$BIN/trace-vk" devices 2>&1 | grep -q "rt-pipeline: supported" && METHODS=$METHODS,rt-pipeline
SCENES=()
for n in $SCENE_NAMES; do
  if "$BIN/bvhc" compile "scenes/$n.toml" -o "$WORK/scenes/$n.bvh" --quiet; then
    SCENES+=("$WORK/scenes/$n.bvh")
  else
    log "bvhc failed on scenes/$n.toml"
  fi
done
[ ${#SCENES[@]} -gt 0 ] || exit 1
log "bench: ${SCENES[*]}, $RES, $MODES, $METHODS"
"$BIN/trace-vk" bench "${SCENES[@]}" --cameras medium --res "$RES" --modes "$MODES" --methods "$METHODS" \
  --persistent off,on,auto --persistent-refill "$REFILLS" --frames "$FRAMES" --csv "$OUT/bench.csv" \
  || log "bench FAILED (exit $?)"
log "bench done"

# Columns of the bench CSV: 1 scene, 6 mode, 8 method, 9 median_ms, 10 min_ms, 11 primary,
# 12 shadow, 13 secondary, 14 ao, 15 diffuse, 16 mrays_per_s. A method name is METHOD, then
# +plain, or +persistent and/or +refillN (tools/src/vk_bench.rs, method_name).
{
  echo "# Persistent threads per mode: $(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null || echo '?')"
  echo
  echo "Scenes $SCENE_NAMES, medium camera, $RES, median of $FRAMES frames; one \`trace-vk bench\` run, every figure side by side."
  echo
  echo "## Mrays/s of the whole frame"
  echo
  echo "| scene | mode | method | plain | on 8 | on 16 | auto 8 | auto 16 | on8/plain | on16/plain | auto16/plain |"
  echo "|---|---|---|--:|--:|--:|--:|--:|--:|--:|--:|"
  [ -f "$OUT/bench.csv" ] && awk -F, '
    $2 == "triangles" { next }
    {
      m = $8; v = "plain"
      if (m ~ /\+plain$/) { sub(/\+plain$/, "", m) }
      else if (m ~ /\+persistent\+refill[0-9]+$/) { r = m; sub(/.*\+refill/, "", r); sub(/\+persistent\+refill[0-9]+$/, "", m); v = "on" r }
      else if (m ~ /\+persistent$/) { next }
      else if (m ~ /\+refill[0-9]+$/) { r = m; sub(/.*\+refill/, "", r); sub(/\+refill[0-9]+$/, "", m); v = "auto" r }
      else if (m == "lst" || m == "stackless") { v = "auto16" }
      key = $1 SUBSEP $6 SUBSEP m
      x[key, v] = $16
      if (!(key in seen)) { seen[key] = 1; order[++k] = key }
    }
    function cell(key, v) { return (key SUBSEP v) in x ? sprintf("%.0f", x[key, v]) : "-" }
    function ratio(key, v) { return ((key SUBSEP v) in x && x[key, "plain"] > 0) ? sprintf("%.2f", x[key, v] / x[key, "plain"]) : "-" }
    END {
      for (i = 1; i <= k; i++) {
        split(order[i], p, SUBSEP); key = order[i]
        printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", p[1], p[2], p[3], cell(key, "plain"), \
          cell(key, "on8"), cell(key, "on16"), cell(key, "auto8"), cell(key, "auto16"), \
          ratio(key, "on8"), ratio(key, "on16"), ratio(key, "auto16")
      }
    }' "$OUT/bench.csv"
  echo
  echo "## Ours against rt-pipeline per kind of ray (cast: the frame; others: added rays over added time)"
  echo
  echo "| scene | ray type | best plain of ours | best default (auto 16) | best of any variant | rt-pipeline | plain/rt | default/rt | any/rt |"
  echo "|---|---|---|---|---|--:|--:|--:|--:|"
  [ -f "$OUT/bench.csv" ] && awk -F, '
    $2 == "triangles" { next }
    {
      m = $8; v = "plain"
      if (m ~ /\+plain$/) { sub(/\+plain$/, "", m) }
      else if (m ~ /\+persistent\+refill[0-9]+$/) { r = m; sub(/.*\+refill/, "", r); sub(/\+persistent\+refill[0-9]+$/, "", m); v = "on" r }
      else if (m ~ /\+persistent$/) { next }
      else if (m ~ /\+refill[0-9]+$/) { r = m; sub(/.*\+refill/, "", r); sub(/\+refill[0-9]+$/, "", m); v = "auto" r }
      else if (m == "lst" || m == "stackless") { v = "auto16" }
      key = $1 SUBSEP $6 SUBSEP m SUBSEP v
      ms[key] = $9; rays[key] = $11 + $12 + $13 + $14 + $15; added[key] = $12 + $13 + $14 + $15
      if (!(($1 SUBSEP $6) in seen)) { seen[$1 SUBSEP $6] = 1; order[++k] = $1 SUBSEP $6 }
      variants[$1 SUBSEP $6] = variants[$1 SUBSEP $6] " " m SUBSEP v
    }
    # Mrays/s of a kind of ray: the cast frame, or what a mode adds to the cast frame of the same
    # method and variant over the time it adds (0 without that cast row).
    function rate(scene, mode, mv,   kc, km, dt) {
      km = scene SUBSEP mode SUBSEP mv
      if (mode == "cast") return rays[km] / ms[km] / 1000
      kc = scene SUBSEP "cast" SUBSEP mv; dt = ms[km] - ms[kc]
      return ((kc in ms) && dt > 0) ? added[km] / dt / 1000 : 0
    }
    function kind(mode) { return mode == "cast" ? "primary" : mode ~ /^whitted/ ? "shadow + secondary" : mode ~ /^ao/ ? "AO" : mode }
    END {
      for (i = 1; i <= k; i++) {
        split(order[i], p, SUBSEP); n = split(variants[order[i]], list, " ")
        bp = bd = ba = rt = 0; np = nd = na = "-"
        for (j = 1; j <= n; j++) {
          split(list[j], mv, SUBSEP); x = rate(p[1], p[2], list[j])
          if (mv[1] == "rt-pipeline") { rt = x; continue }
          if (mv[2] == "plain" && x > bp) { bp = x; np = mv[1] }
          if (mv[2] == "auto16" && x > bd) { bd = x; nd = mv[1] }
          if (x > ba) { ba = x; na = mv[1] " " mv[2] }
        }
        rp = rd = ra = "-"
        if (rt > 0) { rp = sprintf("%.2f", bp / rt); rd = sprintf("%.2f", bd / rt); ra = sprintf("%.2f", ba / rt) }
        printf "| %s | %s | %s %.0f | %s %.0f | %s %.0f | %.0f | %s | %s | %s |\n", p[1], kind(p[2]), np, bp, nd, bd, na, ba, rt, rp, rd, ra
      }
    }' "$OUT/bench.csv"
} >"$OUT/summary.md"
cat "$OUT/summary.md"
log "done"
