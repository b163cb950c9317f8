#!/usr/bin/env bash
# Issue 9 item 5: a million executions of each importer fuzz target (OBJ, glTF/GLB, scene
# description), on a host without a Rust toolchain. Run from the repository root after
# tools/scripts/fuzz-build.sh has filled .fuzzbin/ (binaries, seeds). About 2 to 5 minutes on
# 16 cores.
#
# Each target gets JOBS libFuzzer processes (default: the cores shared by the three targets),
# RUNS/JOBS executions each (RUNS default 1,000,000), one shared corpus started from the seeds,
# -timeout=10 s per input and -rss_limit_mb=2048, and -max_total_time=MAX_TIME (default 480 s)
# so that the run ends within the device's 10 minutes even if a target is slower than expected.
# Writes into $OUT (default out/fuzz): <target>/fuzz-<job>.log, artifacts/<target>/ (crash,
# timeout and out-of-memory inputs), summary.txt with one line per target:
#   <target>: <executions> executions in <jobs> jobs, <crashes> crashes
# and exits 1 when a target crashed or stopped short of RUNS executions.
# What to look for: every line with 0 crashes and at least 1000000 executions.
set -uo pipefail
OUT=${OUT:-out/fuzz}
RUNS=${RUNS:-1000000}
MAX_TIME=${MAX_TIME:-480}
BIN=${FUZZBIN:-.fuzzbin}
TARGETS=(obj gltf description)
JOBS=${JOBS:-$(( $(nproc) / ${#TARGETS[@]} > 0 ? $(nproc) / ${#TARGETS[@]} : 1 ))}
PER_JOB=$(( (RUNS + JOBS - 1) / JOBS ))
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
BIN=$(cd "$BIN" 2>/dev/null && pwd) || { echo "missing .fuzzbin: run tools/scripts/fuzz-build.sh first" >&2; exit 1; }
for t in "${TARGETS[@]}"; do
  [ -x "$BIN/$t" ] || { echo "missing $BIN/$t: run tools/scripts/fuzz-build.sh first" >&2; exit 1; }
done
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
export RAYON_NUM_THREADS=1
echo "fuzzing ${TARGETS[*]}: $JOBS jobs x $PER_JOB runs each on $(nproc) cores, $(cat "$BIN/commit.txt" 2>/dev/null)" |
  tee "$OUT/summary.txt"
pids=()
for t in "${TARGETS[@]}"; do
  mkdir -p "$OUT/$t" "$OUT/artifacts/$t" "$WORK/corpus/$t"
  cp "$BIN/seeds/$t"/* "$WORK/corpus/$t/"
  # -jobs with -workers runs JOBS independent processes, each logging into fuzz-<job>.log in
  # the current folder.
  (cd "$OUT/$t" && exec "$BIN/$t" "$WORK/corpus/$t" \
    -jobs="$JOBS" -workers="$JOBS" -runs="$PER_JOB" -max_total_time="$MAX_TIME" \
    -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$OUT/artifacts/$t/" >"$OUT/$t/driver.log" 2>&1) &
  pids+=($!)
done
for p in "${pids[@]}"; do wait "$p"; done
status=0
for t in "${TARGETS[@]}"; do
  # libFuzzer ends each job's log with "Done N runs in S second(s)" (absent when it crashed);
  # stat::number_of_executed_units covers both.
  runs=$(cat "$OUT/$t"/fuzz-*.log 2>/dev/null | sed -n 's/^stat::number_of_executed_units: *//p' |
    awk '{s += $1} END {print s + 0}')
  crashes=$(find "$OUT/artifacts/$t" -type f | wc -l)
  secs=$(cat "$OUT/$t"/fuzz-*.log 2>/dev/null | sed -n 's/^Done [0-9]* runs in \([0-9]*\) second.*/\1/p' |
    sort -n | tail -1)
  line="$t: $runs executions in $JOBS jobs (longest ${secs:-?} s), $crashes crashes"
  echo "$line" | tee -a "$OUT/summary.txt"
  if [ "$crashes" -gt 0 ] || [ "$runs" -lt "$RUNS" ]; then status=1; fi
done
for t in "${TARGETS[@]}"; do
  if [ -n "$(ls -A "$OUT/artifacts/$t")" ]; then
    echo "--- $t: first crash report" >>"$OUT/summary.txt"
    grep -h -m1 -B2 -A25 -E "ERROR: libFuzzer|panicked at|==ERROR" "$OUT/$t"/fuzz-*.log | head -60 >>"$OUT/summary.txt"
  fi
done
exit $status
