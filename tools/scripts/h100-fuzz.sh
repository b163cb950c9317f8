#!/usr/bin/env bash
# Issue 9 item 5: a million executions of each importer fuzz target (OBJ, glTF/GLB, scene
# description), on a host without a Rust toolchain. Run from the repository root after
# tools/scripts/fuzz-build.sh has filled .fuzzbin/ (binaries, seeds). About 3 to 9 minutes on
# 16 cores.
#
# Each target gets several libFuzzer processes (the cores shared among the targets, below),
# RUNS/jobs executions each (RUNS default 1,000,000), one shared corpus started from the seeds,
# -timeout=30 s per input (a 4-million-triangle description takes 11 s under AddressSanitizer
# on a loaded 2-core machine) and -rss_limit_mb=2048, and -max_total_time=MAX_TIME (default 520 s)
# so that the run ends within the device's 10 minutes even if a target is slower than expected.
# Writes into $OUT (default out/fuzz): <target>/fuzz-<job>.log, artifacts/<target>/ (crash,
# timeout and out-of-memory inputs), summary.txt with one line per target:
#   <target>: <executions> executions in <jobs> jobs (longest <seconds> s), <crashes> crashes
# and exits 1 when a target crashed or stopped short of RUNS executions.
# What to look for: every line with 0 crashes and at least 1000000 executions.
set -uo pipefail
OUT=${OUT:-out/fuzz}
RUNS=${RUNS:-1000000}
MAX_TIME=${MAX_TIME:-520}
BIN=${FUZZBIN:-.fuzzbin}
TARGETS=(obj gltf description)
# Jobs per target: the description target runs about half as many inputs per second as the
# other two (it builds a tree for every small scene), so it gets 3/8 of the cores, the others
# 5/16 each (16 cores: 5, 5, 6). JOBS sets one count for all.
CORES=$(nproc)
jobs_for() {
  local n
  if [ -n "${JOBS:-}" ]; then n=$JOBS
  elif [ "$1" = description ]; then n=$(( CORES * 3 / 8 ))
  else n=$(( CORES * 5 / 16 )); fi
  echo $(( n > 0 ? n : 1 ))
}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
BIN=$(cd "$BIN" 2>/dev/null && pwd) || { echo "missing .fuzzbin: run tools/scripts/fuzz-build.sh first" >&2; exit 1; }
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
for t in "${TARGETS[@]}"; do
  [ -f "$BIN/$t.gz" ] || { echo "missing $BIN/$t.gz: run tools/scripts/fuzz-build.sh first" >&2; exit 1; }
  gzip -dc "$BIN/$t.gz" >"$WORK/$t" && chmod +x "$WORK/$t"
done
export RAYON_NUM_THREADS=1
echo "fuzzing ${TARGETS[*]}: $RUNS executions each on $CORES cores, commit $(cat "$BIN/commit.txt" 2>/dev/null)" |
  tee "$OUT/summary.txt"
pids=()
for t in "${TARGETS[@]}"; do
  jobs=$(jobs_for "$t")
  per_job=$(( (RUNS + jobs - 1) / jobs ))
  mkdir -p "$OUT/$t" "$OUT/artifacts/$t" "$WORK/corpus/$t"
  cp "$BIN/seeds/$t"/* "$WORK/corpus/$t/"
  # -jobs with -workers runs that many independent processes, each logging into fuzz-<job>.log in
  # the current folder.
  (cd "$OUT/$t" && exec "$WORK/$t" "$WORK/corpus/$t" \
    -jobs="$jobs" -workers="$jobs" -runs="$per_job" -max_total_time="$MAX_TIME" \
    -timeout=30 -rss_limit_mb=2048 -print_final_stats=1 \
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
  line="$t: $runs executions in $(jobs_for "$t") jobs (longest ${secs:-?} s), $crashes crashes"
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
