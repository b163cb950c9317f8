#!/usr/bin/env bash
# Issue 17's figures on a many-core host (made for the H100 machine's 16-core host): how close
# `trace-cpu render` comes to the speed of its own rays and of the ray report, 1 thread against
# all, peak memory of large frames, and `trace-cpu bench` beside `trace-vk bench` for one chart.
# About 3 to 4 minutes on 16 cores.
#
# Run from the repository root. Expects release binaries in .bin/ and scenes in .bin/scenes/:
#   .bin/trace-cpu .bin/trace-vk .bin/bvhc     cargo build --release -p tools
#   .bin/render_report                         cargo build --release -p tracer-cpu --example render_report
#   .bin/bench_chart (optional)                cargo build --release -p tools --example bench_chart
#   .bin/scenes/dragon.bvh, room.bvh           bvhc compile scenes/dragon.toml -o .bin/scenes/dragon.bvh
#                                              (or the .toml with its mesh; compiled here then)
# Writes everything into $OUT (default ./out/cpu-h100): summary.md first of all, and the raw
# outputs it was made from.
set -euo pipefail
# SIZE and BIG (the sizes of the memory table) only shrink a trial run on a small machine.
OUT=${OUT:-out/cpu-h100}
SIZE=${SIZE:-1920x1440}
BIG=${BIG:-1920x1440 4096x4096 16384x16384}
mkdir -p "$OUT"
BIN=.bin
ALL=$(nproc)
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*" | tee -a "$OUT/log.txt" >&2; }

for b in trace-cpu trace-vk bvhc render_report; do
  [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)" >&2; exit 1; }
done

# A compiled scene for NAME: .bin/scenes/NAME.bvh, or NAME.toml compiled into $OUT once.
scene() {
  local n=$1
  if [ -f "$BIN/scenes/$n.bvh" ]; then echo "$BIN/scenes/$n.bvh"; return; fi
  if [ ! -f "$OUT/scenes/$n.bvh" ]; then
    mkdir -p "$OUT/scenes"
    "$BIN/bvhc" compile "$BIN/scenes/$n.toml" -o "$OUT/scenes/$n.bvh" >>"$OUT/log.txt" 2>&1
  fi
  echo "$OUT/scenes/$n.bvh"
}
DRAGON=$(scene dragon)
ROOM=$(scene room)

{
  echo "# trace-cpu on $(hostname): issue 17's measurements"
  echo
  echo "- CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), nproc = $ALL"
  echo "- Load average before: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "- Date: $(date -u '+%Y-%m-%d %H:%M UTC'); script: tools/scripts/cpu-h100.sh; git: $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
  echo "- Scene files: dragon $(stat -c %s "$DRAGON") bytes, room $(stat -c %s "$ROOM") bytes"
  echo
} >"$OUT/summary.md"

# 1. The render against its own rays traced alone and against the ray report's primary pass
#    (render_report interleaves the three, medians of at least 5 rounds and 2 s).
log "render_report: dragon and room, $SIZE, cast and Whitted, packets, 1 and $ALL threads"
"$BIN/render_report" --scene dragon="$DRAGON" --scene room="$ROOM" --size "$SIZE" \
  --threads "1,$ALL" --modes cast,whitted --methods packet --reps 5 \
  --out "$OUT/render-report.md" >/dev/null 2>>"$OUT/log.txt"
log "render_report: ordered and stackless, dragon, $ALL threads"
"$BIN/render_report" --scene dragon="$DRAGON" --size "$SIZE" --threads "$ALL" \
  --modes cast,whitted --methods ordered,stackless --reps 5 \
  --out "$OUT/render-report-scalar.md" >/dev/null 2>>"$OUT/log.txt"

# 2. `trace-cpu render` as a user runs it: the rate its timing line prints, median of repeats.
#    The rate covers tracing and shading into the 8-bit image, not loading or writing.
rate() { # prints the Mrays/s of one run's timing line
  sed -n 's/.*(\([0-9.]*\) \([kMG]\)\{0,1\}rays\/s).*/\1 \2/p' | awk '{m=$1; if($2=="G")m*=1000; if($2=="k")m/=1000; if($2=="")m/=1e6; printf "%.2f\n", m}'
}
median() { sort -g | awk '{a[NR]=$1} END {if (NR%2) print a[(NR+1)/2]; else printf "%.2f\n", (a[NR/2]+a[NR/2+1])/2}'; }
{
  echo "## trace-cpu render, dragon $SIZE, camera medium: Mrays/s from the timing line (median of runs)"
  echo
  echo "| mode | threads | runs | median Mrays/s | all runs |"
  echo "|---|---:|---:|---:|---|"
} >>"$OUT/summary.md"
for mode in cast whitted; do
  for t in 1 "$ALL"; do
    runs=5; [ "$t" = 1 ] && runs=3
    log "trace-cpu render dragon $mode, $t threads, $runs runs"
    rates=()
    for _ in $(seq "$runs"); do
      r=$("$BIN/trace-cpu" render "$DRAGON" --camera medium --mode "$mode" --res "$SIZE" --threads "$t" \
        -o "$OUT/dragon-$mode.png" 2>>"$OUT/log.txt" | tee -a "$OUT/render-lines.txt" | rate)
      rates+=("$r")
    done
    echo "| $mode | $t | $runs | $(printf '%s\n' "${rates[@]}" | median) | ${rates[*]} |" >>"$OUT/summary.md"
  done
done

# 3. Peak memory of large frames (issue 17: within the scene file + 200 MB at 4096x4096; issue 15
#    item 4: 16384x16384 works), with the rate and wall time.
{
  echo
  echo "## Peak memory (/usr/bin/time -v), dragon, cast, $ALL threads, PNG written"
  echo
  echo "| size | max RSS MB | scene file MB | RSS - file MB | wall s | timing line |"
  echo "|---|---:|---:|---:|---:|---|"
} >>"$OUT/summary.md"
file_mb=$(( $(stat -c %s "$DRAGON") / 1000000 ))
for res in $BIG; do
  log "memory: trace-cpu render dragon $res"
  if [ -x /usr/bin/time ]; then
    timeout 120 /usr/bin/time -v "$BIN/trace-cpu" render "$DRAGON" --camera medium --mode cast --res "$res" \
      -o "$OUT/big.png" >"$OUT/mem-$res.out" 2>"$OUT/mem-$res.time" || echo "failed or timed out: $res" >>"$OUT/log.txt"
    rss_mb=$(( $(sed -n 's/.*Maximum resident set size (kbytes): //p' "$OUT/mem-$res.time") / 1000 ))
    wall=$(sed -n 's/.*Elapsed (wall clock) time (h:mm:ss or m:ss): //p' "$OUT/mem-$res.time")
  else
    rss_mb='?'; wall='?'
    "$BIN/trace-cpu" render "$DRAGON" --camera medium --mode cast --res "$res" -o "$OUT/big.png" >"$OUT/mem-$res.out"
  fi
  diff_mb='?'; [ "$rss_mb" != '?' ] && diff_mb=$((rss_mb - file_mb))
  echo "| $res | $rss_mb | $file_mb | $diff_mb | $wall | $(head -c 160 "$OUT/mem-$res.out") |" >>"$OUT/summary.md"
  rm -f "$OUT/big.png"
done

# 4. trace-cpu bench beside trace-vk bench: the same matrix and columns, one CSV each, for the chart.
log "trace-cpu bench: dragon and room, medium, $SIZE, cast/whitted1/whitted2, 3 methods, $ALL threads"
"$BIN/trace-cpu" bench "$DRAGON" "$ROOM" --cameras medium --res "$SIZE" --modes cast,whitted1,whitted2 \
  --methods packet,ordered,stackless --frames 5 --warmup 1 --csv "$OUT/bench-cpu.csv" >/dev/null 2>>"$OUT/log.txt"
log "trace-cpu bench: the same, packets, 1 thread"
"$BIN/trace-cpu" bench "$DRAGON" "$ROOM" --cameras medium --res "$SIZE" --modes cast,whitted1,whitted2 \
  --methods packet --frames 3 --warmup 1 --threads 1 --csv "$OUT/bench-cpu-1thread.csv" >/dev/null 2>>"$OUT/log.txt"
log "trace-vk bench: the same matrix"
"$BIN/trace-vk" bench "$DRAGON" "$ROOM" --cameras medium --res "$SIZE" --modes cast,whitted1,whitted2 \
  --methods lst,stackless,sst --frames 20 --warmup 3 --csv "$OUT/bench-vk.csv" >/dev/null 2>>"$OUT/log.txt" \
  || log "trace-vk bench failed (no GPU?): the chart has CPU rows only"
if [ -x "$BIN/bench_chart" ]; then
  csvs=("$OUT/bench-cpu.csv" "$OUT/bench-cpu-1thread.csv")
  [ -f "$OUT/bench-vk.csv" ] && csvs+=("$OUT/bench-vk.csv")
  "$BIN/bench_chart" "${csvs[@]}" -o "$OUT/bench-chart.svg" >>"$OUT/log.txt" 2>&1 || log "bench_chart failed"
fi

{
  echo
  echo "## render_report: render against its rays traced alone and the ray report (packets)"
  echo
  cat "$OUT/render-report.md"
  echo
  echo "## render_report: scalar traversals, $ALL threads"
  echo
  cat "$OUT/render-report-scalar.md"
  echo
  echo "## trace-cpu bench, $ALL threads"
  echo
  cat "$OUT/bench-cpu.md"
  echo
  echo "## trace-cpu bench, 1 thread"
  echo
  cat "$OUT/bench-cpu-1thread.md"
  if [ -f "$OUT/bench-vk.md" ]; then
    echo
    echo "## trace-vk bench"
    echo
    cat "$OUT/bench-vk.md"
  fi
  echo
  echo "- Load average after: $(cut -d' ' -f1-3 /proc/loadavg); $(($(date +%s) - START)) s in all"
} >>"$OUT/summary.md"
rm -f "$OUT"/dragon-*.png
log "done: $OUT/summary.md"
