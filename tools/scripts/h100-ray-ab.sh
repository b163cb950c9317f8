#!/usr/bin/env bash
# Builds of the ray report side by side on the 16-core host: each VARIANT's ray report run in
# turn, ROUNDS times, so that a tracer-cpu change is judged by its ratio to Embree measured in
# the same run, and by that ratio's median over rounds against the other variants' (the host
# drifts by several points between runs of one binary: docs/cpu-benchmark.md).
#
# VARIANTS: space-separated NAME or NAME:VAR=VALUE[,VAR=VALUE] (environment for that run); NAME
# picks .bin/ray_report_NAME. Env: ENGINES (default "ours bvh8,Embree 1"), KINDS (default all),
# SCENES (default bunny dragon million), SIZE (default 1920x1440), THREADS (default 1,16), REPS
# (default 5), ROUNDS (default 2), COLUMN (the ratio column's header, default "bvh8 / Embree 1";
# several, comma-separated, make one table each).
# Carry .bin with ray_report_NAME (or ray_report_NAME.xz) and embree.txz (h100-simd.sh says how
# to make them). Writes $OUT: each run's Markdown, and summary.md (per row: each variant's median
# ratio over the rounds, the rounds in brackets). With SUMMARY_ONLY=1 it runs nothing and only
# writes summary.md again from the Markdown already in $OUT (another COLUMN, say).
set -uo pipefail
OUT=${OUT:-out/h100-ray-ab}
VARIANTS=${VARIANTS:?name the variants, e.g. VARIANTS="base new"}
ENGINES=${ENGINES:-ours bvh8,Embree 1}
KINDS=${KINDS:-primary,shadow,secondary,ao,diffuse}
SCENES=${SCENES:-bunny dragon million}
SIZE=${SIZE:-1920x1440}
THREADS=${THREADS:-1,16}
REPS=${REPS:-5}
ROUNDS=${ROUNDS:-2}
COLUMN=${COLUMN:-bvh8 / Embree 1}
mkdir -p "$OUT"
if [ "${SUMMARY_ONLY:-0}" = 1 ]; then
  ROUNDS=0
else
  if [ -f .bin/embree.txz ] && [ ! -d .bin/embree ]; then tar xJf .bin/embree.txz -C .bin; fi
  for f in .bin/ray_report_*.xz; do [ -e "$f" ] && xz -d "$f" && chmod +x "${f%.xz}"; done
  if [ -d .bin/embree/usr/lib/x86_64-linux-gnu ]; then
    export LD_LIBRARY_PATH=$PWD/.bin/embree/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
  fi
  { nproc; uptime; grep -m1 "model name" /proc/cpuinfo; cat /sys/kernel/mm/transparent_hugepage/enabled; } >"$OUT/host.txt"
fi
ARGS=()
for s in $SCENES; do ARGS+=(--scene "$s=scenes/$s.toml"); done
for r in $(seq 1 "$ROUNDS"); do
  for v in $VARIANTS; do
    name=${v%%:*}
    envs=()
    [ "$name" != "$v" ] && IFS=, read -ra envs <<<"${v#*:}"
    tag=$(echo "$v" | tr ':=,/' '_-__')
    echo "== $tag $r $(date -u +%H:%M:%S) load $(cut -d' ' -f1 /proc/loadavg)"
    env "${envs[@]}" ".bin/ray_report_$name" "${ARGS[@]}" --sizes "$SIZE" --threads "$THREADS" --reps "$REPS" \
      --kinds "$KINDS" --engines "$ENGINES" --out "$OUT/$tag-$r.md" >"$OUT/$tag-$r.log" 2>&1 ||
      { echo "$tag $r FAILED"; tail -5 "$OUT/$tag-$r.log"; }
  done
done
# The targets table per COLUMN: columns scene, (size, where the runs had several,) kind, threads,
# then each variant's median ratio.
IFS=, read -ra COLUMNS <<<"$COLUMN"
for COLUMN in "${COLUMNS[@]}"; do
[ ${#COLUMNS[@]} -gt 1 ] && printf "\n### %s\n\n" "$COLUMN"
{
  for v in $VARIANTS; do
    tag=$(echo "$v" | tr ':=,/' '_-__')
    for f in "$OUT/$tag"-*.md; do
      awk -F'|' -v col="$COLUMN" -v tag="$v" '
        /^\| scene \| size \| kind \| threads \|/ && !done { for (i = 1; i <= NF; i++) if ($i ~ "^ *" col " *$") c = i; on = c > 0; next }
        on && /^\|---/ { next }
        on && /^\|/ { gsub(/ /, "", $2); gsub(/ /, "", $3); gsub(/ /, "", $4); gsub(/ /, "", $5); gsub(/[ %]/, "", $c); print tag "," $2 "," $3 "," $4 "," $5 "," $c; next }
        on { on = 0; done = 1 }' "$f"
    done
  done | awk -F, -v vars="$VARIANTS" '
    { k = $2 "|" $3 "|" $4 "|" $5; r[$1, k] = r[$1, k] " " $6; if (!(k in seen)) { seen[k] = 1; o[++n] = k }; if (!($3 in sz)) { sz[$3] = 1; sizes++ } }
    function med(s,   a, c, i, j, x) { c = split(s, a, " "); if (!c) return "-"; for (i = 1; i <= c; i++) for (j = i + 1; j <= c; j++) if (a[j] + 0 < a[i] + 0) { x = a[i]; a[i] = a[j]; a[j] = x }; return c % 2 ? a[(c + 1) / 2] "%" : (a[c / 2] + a[c / 2 + 1]) / 2 "%" }
    END {
      m = split(vars, vs, " ")
      printf "| scene |%s kind | threads |", (sizes > 1 ? " size |" : "")
      for (j = 1; j <= m; j++) printf " %s |", vs[j]
      printf "\n|---|%s---|--:|", (sizes > 1 ? "---|" : "")
      for (j = 1; j <= m; j++) printf "--:|"
      printf "\n"
      for (i = 1; i <= n; i++) {
        split(o[i], p, "|")
        if (sizes > 1) printf "| %s | %s | %s | %s |", p[1], p[2], p[3], p[4]; else printf "| %s | %s | %s |", p[1], p[3], p[4]
        for (j = 1; j <= m; j++) printf " %s (%s) |", med(r[vs[j], o[i]]), substr(r[vs[j], o[i]], 2)
        printf "\n"
      }
    }'
}
done | tee "$OUT/summary.md"
