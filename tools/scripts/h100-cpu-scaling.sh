#!/usr/bin/env bash
# Issue 17's scaling target (16 threads >= 12x one thread on the dragon) read two ways on the H100
# machine's 16-core host: `trace-cpu bench` (the median of repeated frames in one process, the way
# trace-vk bench times the GPU; its Whitted mode is whitted1, one light) and `trace-cpu render`'s
# own timing line (one frame per process, as a user runs it, with the scene's lights; its first
# traversal meets a cold cache and TLB), RUNS processes each.
# Run from the repository root with release binaries in .bin/ (trace-cpu, bvhc; see
# h100-cpurender.sh's header). Device tool: command `bash tools/scripts/h100-cpu-scaling.sh`,
# carry [".bin"]. Writes $OUT (default out/h100-cpu-scaling): bench-T.csv/.md per thread count,
# render-lines.txt, summary.md (the medians and the 16 / 1 thread ratios; also on stdout).
# About 2 minutes.
set -euo pipefail
OUT=${OUT:-out/h100-cpu-scaling}
RUNS=${RUNS:-9}
FRAMES=${FRAMES:-15}
THREADS=${THREADS:-"1 8 $(nproc)"}
METHODS=${METHODS:-auto,packet}
mkdir -p "$OUT"
.bin/bvhc compile scenes/dragon.toml -o "$OUT/dragon.bvh" >/dev/null
{
  echo "# trace-cpu on the dragon, 1920x1440, camera medium: scaling with threads"
  echo
  echo "- CPU: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //'), nproc = $(nproc); load before: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "- Date: $(date -u '+%Y-%m-%d %H:%M UTC'); script: tools/scripts/h100-cpu-scaling.sh (RUNS=$RUNS, FRAMES=$FRAMES)"
  echo
} >"$OUT/summary.md"
for t in $THREADS; do
  .bin/trace-cpu bench "$OUT/dragon.bvh" --cameras medium --res 1920x1440 --modes cast,whitted1 \
    --methods "$METHODS" --frames "$FRAMES" --threads "$t" --csv "$OUT/bench-$t.csv" >>"$OUT/log.txt" 2>&1 \
    || { echo "trace-cpu bench failed on $t threads (see $OUT/log.txt)" >&2; exit 1; }
  for mode in cast whitted; do
    for m in ${METHODS//,/ }; do
      for _ in $(seq "$RUNS"); do
        .bin/trace-cpu render "$OUT/dragon.bvh" --mode "$mode" --method "$m" --res 1920x1440 \
          --threads "$t" -o "$OUT/frame.png" 2>&1 | grep 'Mrays/s' | sed "s/^/$mode $m $t: /" >>"$OUT/render-lines.txt"
      done
    done
  done
done
{
  echo "## trace-cpu render's timing line: median Mrays/s of $RUNS processes"
  echo
  echo "| mode | method | $(echo $THREADS | sed 's/ / threads | /g') threads | $(echo $THREADS | awk '{print $NF}') / 1 |"
  echo "|---|---|$(for _ in $THREADS; do printf -- '--:|'; done)--:|"
  for mode in cast whitted; do
    for m in ${METHODS//,/ }; do
      row="| $mode | $m |"; first=; last=
      for t in $THREADS; do
        med=$(grep "^$mode $m $t: " "$OUT/render-lines.txt" | grep -o '[0-9.]* Mrays/s' | cut -d' ' -f1 | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')
        row="$row $med |"; [ -z "$first" ] && first=$med; last=$med
      done
      echo "$row $(awk -v a="$last" -v b="$first" 'BEGIN { printf "%.1fx", a / b }') |"
    done
  done
  echo
  echo "## trace-cpu bench (median of $FRAMES frames in one process), per thread count"
  for t in $THREADS; do echo; echo "### $t threads"; echo; cat "$OUT/bench-$t.md"; done
} >>"$OUT/summary.md"
cat "$OUT/summary.md"
