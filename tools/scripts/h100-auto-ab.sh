#!/usr/bin/env bash
# `trace-cpu bench` of several builds side by side on the 16-core host: each VARIANT's binary
# runs the same matrix in turn, ROUNDS times, so that a renderer change (what `--method auto`
# picks, say) is judged by frame times measured in the same run; the host drifts by several
# points between runs of one binary (docs/cpu-benchmark.md).
#
# VARIANTS: space-separated NAME=METHODS, NAME picking .bin/trace-cpu_NAME (or its .xz) and
# METHODS its `--methods` list, e.g. VARIANTS="main=auto new=auto,bvh8-packet,packet,bvh8".
# Env: SCENES (default bunny dragon million: scenes/NAME.toml compiled here by .bin/bvhc), MODES
# (default cast,whitted1,ao8,diffuse), RES (default 1920x1440), THREADS (space-separated, default
# all cores), FRAMES (default 10), ROUNDS (default 3).
# Writes $OUT: each run's CSV and Markdown, and summary.md: per scene, mode, threads and
# VARIANT/method the median over the rounds of each round's median frame time (ms), the rounds
# in brackets, and its ratio to the first column. With SUMMARY_ONLY=1 it runs nothing and only
# writes summary.md again from the CSV already in $OUT.
set -uo pipefail
OUT=${OUT:-out/h100-auto-ab}
VARIANTS=${VARIANTS:?name the variants, e.g. VARIANTS="main=auto new=auto,bvh8-packet"}
SCENES=${SCENES:-bunny dragon million}
MODES=${MODES:-cast,whitted1,ao8,diffuse}
RES=${RES:-1920x1440}
THREADS=${THREADS:-$(nproc)}
FRAMES=${FRAMES:-10}
ROUNDS=${ROUNDS:-3}
mkdir -p "$OUT/scenes"
[ "${SUMMARY_ONLY:-0}" = 1 ] && ROUNDS=0 SCENES=
for f in .bin/trace-cpu_*.xz .bin/bvhc.xz; do [ -e "$f" ] && xz -d "$f" && chmod +x "${f%.xz}"; done
[ "$ROUNDS" = 0 ] || { nproc; uptime; grep -m1 "model name" /proc/cpuinfo; } >"$OUT/host.txt"
FILES=()
for s in $SCENES; do
  .bin/bvhc compile "scenes/$s.toml" -o "$OUT/scenes/$s.bvh" >>"$OUT/compile.log" 2>&1 || { echo "cannot compile $s"; exit 1; }
  FILES+=("$OUT/scenes/$s.bvh")
done
for r in $(seq 1 "$ROUNDS"); do
  for t in $THREADS; do
    for v in $VARIANTS; do
      name=${v%%=*} methods=${v#*=}
      echo "== $name $t threads, round $r $(date -u +%H:%M:%S) load $(cut -d' ' -f1 /proc/loadavg)"
      ".bin/trace-cpu_$name" bench "${FILES[@]}" --cameras medium --res "$RES" --modes "$MODES" \
        --methods "$methods" --frames "$FRAMES" --threads "$t" --csv "$OUT/$name-t$t-$r.csv" \
        >"$OUT/$name-t$t-$r.log" 2>&1 || { echo "$name $t $r FAILED"; tail -5 "$OUT/$name-t$t-$r.log"; }
    done
  done
done
rm -rf "$OUT/scenes"
# summary.md: one row per scene, mode and threads; one column per variant/method with the median
# of the rounds' median_ms, the rounds in brackets, and its ratio to the first column's.
{
  echo "# trace-cpu bench side by side: median frame ms over $ROUNDS rounds (the rounds), ratio to the first column"
  echo
  echo "Variants: $VARIANTS; scenes $SCENES; modes $MODES; $RES; threads $THREADS; $FRAMES frames per setting."
  echo
  for v in $VARIANTS; do
    name=${v%%=*}
    for f in "$OUT/$name"-t*-*.csv; do
      [ -e "$f" ] || continue
      t=${f##*-t}; t=${t%%-*}
      tail -n +2 "$f" | awk -F, -v n="$name" -v t="$t" '{print $1","$6","t","n"/"$8","$9}'
    done
  done | awk -F, '
    { key = $1 "|" $2 "|" $3; col = $4
      if (!(key in seen)) { seen[key] = 1; keys[++nk] = key }
      if (!(col in cseen)) { cseen[col] = 1; cols[++nc] = col }
      v[key, col] = v[key, col] (v[key, col] == "" ? "" : " ") $5 }
    function med(s,   a, n, i, j, x) {
      n = split(s, a, " ")
      for (i = 2; i <= n; i++) { x = a[i] + 0; for (j = i - 1; j >= 1 && a[j] + 0 > x; j--) a[j + 1] = a[j]; a[j + 1] = x }
      return n % 2 ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2 }
    END {
      printf "| scene | mode | threads |"; for (c = 1; c <= nc; c++) printf " %s |", cols[c]; print ""
      printf "|---|---|---:|"; for (c = 1; c <= nc; c++) printf "---:|"; print ""
      for (k = 1; k <= nk; k++) {
        split(keys[k], p, "|"); printf "| %s | %s | %s |", p[1], p[2], p[3]
        base = (v[keys[k], cols[1]] == "") ? 0 : med(v[keys[k], cols[1]])
        for (c = 1; c <= nc; c++) {
          s = v[keys[k], cols[c]]
          if (s == "") { printf " - |"; continue }
          m = med(s); n = split(s, r, " "); list = ""
          for (i = 1; i <= n; i++) list = list (i > 1 ? ", " : "") sprintf("%.1f", r[i])
          printf " %.1f (%s)%s |", m, list, (c > 1 && base > 0) ? sprintf(" %.0f%%", 100 * m / base) : ""
        }
        print ""
      } }'
} >"$OUT/summary.md"
cat "$OUT/summary.md"
