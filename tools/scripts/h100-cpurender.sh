#!/usr/bin/env bash
# Issue 17 on the H100 machine's 16-core host: does `trace-cpu render` trace at the speed of its
# rays on every core? render_report interleaves, per scene, mode, method and thread count, (a) the
# whole render as trace-cpu runs it, (b) the frame's recorded rays traced alone with the same
# tracing code and (c) for ray casting the ray report's pass over the same primary rays; then
# trace-cpu render's own timing lines (median of runs) on 1, 8 and all threads, and the peak
# memory of a 4096x4096 frame. About 5 to 6 minutes on 16 cores (the one-thread rounds of the
# scalar traversals are most of it); the bunny is skipped when the dragon took too long.
#
# Run from the repository root. Expects release binaries in .bin/ (built on the development
# machine; they link only libc, libm and libgcc_s):
#   .bin/trace-cpu .bin/bvhc      cargo build --release -p tools --bin trace-cpu --bin bvhc
#   .bin/render_report            cargo build --release -p tracer-cpu --example render_report
# Scenes: scenes/dragon.toml and scenes/bunny.toml, compiled here with the default settings.
# Device tool: command `bash tools/scripts/h100-cpurender.sh`, carry [".bin"].
#
# Writes $OUT (default out/h100-cpurender): summary.md (read this), log.txt (progress and
# render_report's per-row lines), render-lines.txt (every trace-cpu timing line), mem.txt.
#
# What summary.md holds and what to look for (issue 17's targets):
# - "Issue 17's 80% target, dragon" (first; also printed to stdout at the end): one row per mode x
#   method x threads with `render / ray report` (cast: the ray report's pass over the same primary
#   rays with the engine the frame traces them with) and `render / alone` (the frame's own
#   recorded rays replayed through the same tracing code; the only basis for Whitted, which the
#   ray report has no pass for), and `>= 80%?` judged on the ray report for cast and on the
#   replay for Whitted. The render is what trace-cpu's timing line covers (auto's measurement,
#   tracing, shading into the 8-bit image, its buffers already paged in).
# - "render_report, dragon": one row per mode x method x threads (1, 8, all). `render / ray
#   report` (cast only: the ray report's pass of the engine the frame traces primary rays with)
#   and `render / alone` should be >= 80% on every thread count; `render / 1 thread` on the all-
#   threads rows should be >= 12x. The method column shows auto's pick per kind of ray as that
#   pool measured it.
# - "trace-cpu render, dragon": median Mrays/s of the timing line per mode, method and thread
#   count (3 runs each; the line's time covers auto's measurement, tracing and shading, not
#   loading, the BVH collapse, paging in the image or writing it), and the all-threads / 1-thread
#   ratio (target >= 12x).
# - "Peak memory": max RSS of a 4096x4096 cast against the scene file (target: file + 200 MB).
# - "render_report, bunny": as for the dragon, when time allowed.
#
# Env: SIZE (default 1920x1440), METHODS (render_report, default auto,packet,bvh8,ordered,stackless),
# LINE_METHODS (trace-cpu runs, default "auto packet bvh8"), RUNS (default 3).
set -uo pipefail
OUT=${OUT:-out/h100-cpurender}
SIZE=${SIZE:-1920x1440}
METHODS=${METHODS:-auto,packet,bvh8,ordered,stackless}
LINE_METHODS=${LINE_METHODS:-auto packet bvh8}
RUNS=${RUNS:-3}
BIN=.bin
mkdir -p "$OUT"
ALL=$(nproc)
HALF=$((ALL / 2))
THREADS="1,$HALF,$ALL"
[ "$HALF" -le 1 ] && THREADS="1,$ALL"
START=$(date +%s)
elapsed() { echo $(($(date +%s) - START)); }
log() { echo "[$(elapsed) s] $*" | tee -a "$OUT/log.txt" >&2; }
for b in trace-cpu bvhc render_report; do
  [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)" >&2; exit 1; }
done
# A render_report built in one cargo call with ray_report (`--features embree`) links Embree: use
# h100-simd.sh's copy of its libraries when carried, and say so before the first row fails.
if [ -d .bin/embree/usr/lib/x86_64-linux-gnu ]; then
  export LD_LIBRARY_PATH=$PWD/.bin/embree/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
if ldd "$BIN/render_report" | grep -q 'not found'; then
  echo "render_report cannot find its libraries (built with --features embree? see h100-simd.sh's header):" >&2
  ldd "$BIN/render_report" | grep 'not found' >&2
  exit 1
fi

for n in dragon bunny; do
  "$BIN/bvhc" compile "scenes/$n.toml" -o "$OUT/$n.bvh" >>"$OUT/log.txt" 2>&1 || { log "cannot compile $n"; exit 1; }
done
DRAGON=$OUT/dragon.bvh
BUNNY=$OUT/bunny.bvh

{
  echo "# trace-cpu render against its rays: issue 17 on $(hostname)"
  echo
  echo "- CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), nproc = $ALL; SIMD: $(grep -m1 '^flags' /proc/cpuinfo | tr ' ' '\n' | grep -E '^(avx2|fma|avx512f)$' | tr '\n' ' ')"
  echo "- Load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "- Date: $(date -u '+%Y-%m-%d %H:%M UTC'); script: tools/scripts/h100-cpurender.sh; git: $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
  echo "- Scene files: dragon $(stat -c %s "$DRAGON") bytes, bunny $(stat -c %s "$BUNNY") bytes"
  echo
} >"$OUT/summary.md"

# 1. render_report on the dragon: every method, cast and Whitted, 1, half and all threads.
log "render_report: dragon $SIZE, cast and Whitted, $METHODS, threads $THREADS"
"$BIN/render_report" --scene dragon="$DRAGON" --size "$SIZE" --threads "$THREADS" --modes cast,whitted \
  --methods "$METHODS" --reps 5 --out "$OUT/render-report-dragon.md" >/dev/null 2>>"$OUT/log.txt" \
  || log "render_report on the dragon failed (see log.txt)"
# Issue 17's target per method: render >= 80% of the ray report (cast) or of its own rays traced
# alone (Whitted, which the ray report has no pass for).
target_table() { # $1: a render_report Markdown table
  echo "| mode | method | threads | render Mrays/s | render / ray report | render / alone | >= 80%? |"
  echo "|---|---|---:|---:|---:|---:|---|"
  awk -F'|' '$3 ~ /^ (Cast|Whitted) $/ {
    for (i = 2; i <= 11; i++) gsub(/^ +| +$/, "", $i)
    basis = ($11 ~ /%/) ? $11 : $9; which = ($11 ~ /%/) ? "ray report" : "alone"
    v = basis; sub(/%/, "", v)
    printf "| %s | %s | %s | %s | %s | %s | %s (%s %s) |\n", $3, $4, $5, $7, $11, $9, (v + 0 >= 80) ? "yes" : "NO", which, basis
  }' "$1"
}
{
  echo "## Issue 17's 80% target, dragon $SIZE (render_report; render = trace-cpu's timed region)"
  echo
  target_table "$OUT/render-report-dragon.md" 2>/dev/null
  echo
  echo "## render_report, dragon $SIZE"
  echo
  cat "$OUT/render-report-dragon.md" 2>/dev/null
  echo
} >>"$OUT/summary.md"

# 2. trace-cpu render as a user runs it: the rate its timing line prints, median of RUNS.
rate() { # the Mrays/s of a timing line
  sed -n 's/.*(\([0-9.]*\) \([kMG]\)\{0,1\}rays\/s).*/\1 \2/p' | awk '{m=$1; if($2=="G")m*=1000; if($2=="k")m/=1000; if($2=="")m/=1e6; printf "%.2f\n", m}'
}
median() { sort -g | awk '{a[NR]=$1} END {if (NR%2) print a[(NR+1)/2]; else printf "%.2f\n", (a[NR/2]+a[NR/2+1])/2}'; }
{
  echo "## trace-cpu render, dragon $SIZE, camera medium: Mrays/s of the timing line, median of $RUNS runs"
  echo
  echo "The time covers auto's measurement, tracing and shading into the 8-bit image; not loading, the wide"
  echo "BVH's collapse, paging in the image (printed apart on the line) or writing the PNG."
  echo
  echo "| mode | method | $(echo "$THREADS" | sed 's/,/ threads | /g') threads | $ALL / 1 thread |"
  echo "|---|---|$(echo "$THREADS" | sed 's/[0-9]*/---:/g; s/,/|/g')|---:|"
} >>"$OUT/summary.md"
for mode in cast whitted; do
  for m in $LINE_METHODS; do
    row="| $mode | $m |"
    one=""; all=""
    for t in ${THREADS//,/ }; do
      log "trace-cpu render dragon $mode $m, $t threads, $RUNS runs"
      rates=()
      for _ in $(seq "$RUNS"); do
        r=$("$BIN/trace-cpu" render "$DRAGON" --camera medium --mode "$mode" --res "$SIZE" --method "$m" \
          --threads "$t" -o "$OUT/frame.png" 2>>"$OUT/log.txt" | head -1 | tee -a "$OUT/render-lines.txt" | rate)
        rates+=("${r:-0}")
      done
      med=$(printf '%s\n' "${rates[@]}" | median)
      row="$row $med |"
      [ "$t" = 1 ] && one=$med
      [ "$t" = "$ALL" ] && all=$med
    done
    echo "$row $(awk -v a="$all" -v o="$one" 'BEGIN { if (o > 0) printf "%.1fx", a / o; else print "-" }') |" >>"$OUT/summary.md"
  done
done
rm -f "$OUT/frame.png"

# 3. Peak memory of a 4096x4096 cast on all threads (target: the scene file + 200 MB).
log "peak memory: trace-cpu render dragon 4096x4096 cast"
file_mb=$(( $(stat -c %s "$DRAGON") / 1000000 ))
if [ -x /usr/bin/time ]; then
  /usr/bin/time -v "$BIN/trace-cpu" render "$DRAGON" --camera medium --mode cast --res 4096x4096 --method auto \
    -o "$OUT/big.png" >"$OUT/mem.txt" 2>"$OUT/mem-time.txt"
  rss_mb=$(( $(sed -n 's/.*Maximum resident set size (kbytes): //p' "$OUT/mem-time.txt") / 1000 ))
  how="/usr/bin/time -v"
else
  # Without GNU time: the kernel's high-water mark of the process, read just before it ends.
  "$BIN/trace-cpu" render "$DRAGON" --camera medium --mode cast --res 4096x4096 --method auto -o "$OUT/big.png" \
    >"$OUT/mem.txt" 2>&1 &
  pid=$!; peak=0
  while kill -0 "$pid" 2>/dev/null; do
    hwm=$(sed -n 's/^VmHWM: *\([0-9]*\) kB/\1/p' "/proc/$pid/status" 2>/dev/null); [ -n "$hwm" ] && peak=$hwm
    sleep 0.05
  done
  wait "$pid"; rss_mb=$((peak / 1000)); how="VmHWM sampled every 50 ms (a lower bound)"
fi
{
  echo
  echo "## Peak memory, dragon 4096x4096 cast, $ALL threads, PNG written ($how)"
  echo
  echo "| max RSS MB | scene file MB | RSS - file MB (target <= 200) | timing line |"
  echo "|---:|---:|---:|---|"
  echo "| $rss_mb | $file_mb | $((rss_mb - file_mb)) | $(head -1 "$OUT/mem.txt" | cut -c1-260) |"
  echo
} >>"$OUT/summary.md"
rm -f "$OUT/big.png"

# 4. The bunny, when the dragon left time (the whole run stays under 7 minutes).
if [ "$(elapsed)" -lt 260 ]; then
  log "render_report: bunny $SIZE, cast and Whitted, auto,packet,bvh8, threads $THREADS"
  "$BIN/render_report" --scene bunny="$BUNNY" --size "$SIZE" --threads "$THREADS" --modes cast,whitted \
    --methods auto,packet,bvh8 --reps 5 --out "$OUT/render-report-bunny.md" >/dev/null 2>>"$OUT/log.txt" \
    || log "render_report on the bunny failed (see log.txt)"
  { echo "## render_report, bunny $SIZE"; echo; cat "$OUT/render-report-bunny.md" 2>/dev/null; echo; } >>"$OUT/summary.md"
else
  log "bunny skipped: $(elapsed) s gone"
  echo "## render_report, bunny: skipped ($(elapsed) s gone after the dragon)" >>"$OUT/summary.md"
fi

echo "- Load average after: $(cut -d' ' -f1-3 /proc/loadavg); $(elapsed) s in all" >>"$OUT/summary.md"
# The target table on stdout too, for a reader of the run's output alone.
echo "Issue 17's 80% target, dragon $SIZE ($(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), nproc $ALL):"
target_table "$OUT/render-report-dragon.md" 2>/dev/null
rm -f "$OUT"/*.bvh
log "done: $OUT/summary.md"
