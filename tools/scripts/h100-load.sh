#!/usr/bin/env bash
# What a `trace-cpu render` (or, with TRACER=trace-vk, a `trace-vk render`) spends before and after
# its frame, side by side for several builds on the 16-core host: each VARIANT's binary
# (.bin/TRACER_NAME or its .xz) renders each scene once per round and thread count, the variants
# in turn, ROUNDS rounds. Per run: the process's wall time from outside, the collapse time and the
# frame time it prints (trace-vk: no collapse, its GPU time as the frame).
# Env: VARIANTS (space-separated names, e.g. "main new"), SCENES (default bunny dragon million:
# scenes/NAME.toml compiled here by .bin/bvhc), THREADS (default "1 16"), MODE (default cast), RES
# (default 1920x1440), ROUNDS (default 5), TRACER (default trace-cpu; trace-vk takes no --threads,
# so give it THREADS=-).
# Writes $OUT: runs.csv (variant, scene, threads, round, wall ms, collapse ms, frame ms) and
# summary.md (medians over the rounds, the rounds' range in brackets).
set -uo pipefail
OUT=${OUT:-out/h100-load}
VARIANTS=${VARIANTS:?name the variants, e.g. VARIANTS="main new"}
SCENES=${SCENES:-bunny dragon million}
THREADS=${THREADS:-1 16}
MODE=${MODE:-cast}
RES=${RES:-1920x1440}
ROUNDS=${ROUNDS:-5}
TRACER=${TRACER:-trace-cpu}
mkdir -p "$OUT/scenes"
for f in .bin/"$TRACER"_*.xz .bin/bvhc.xz; do [ -e "$f" ] && xz -d "$f" && chmod +x "${f%.xz}"; done
{ nproc; uptime; grep -m1 "model name" /proc/cpuinfo; echo "THP: $(cat /sys/kernel/mm/transparent_hugepage/enabled), defrag: $(cat /sys/kernel/mm/transparent_hugepage/defrag)"; } >"$OUT/host.txt"
for s in $SCENES; do
  .bin/bvhc compile "scenes/$s.toml" -o "$OUT/scenes/$s.bvh" >>"$OUT/compile.log" 2>&1 || { echo "cannot compile $s"; exit 1; }
done
echo "variant,scene,threads,round,wall_ms,collapse_ms,frame_ms" >"$OUT/runs.csv"
ms() { # the first "<number> <unit> to <what>" of a line, in ms
  grep -o "[0-9.]* [mµ]*s to $2" <<<"$1" | head -1 | awk '{v=$1; if ($2=="s") v*=1000; if ($2=="µs") v/=1000; print v}'
}
for r in $(seq 1 "$ROUNDS"); do
  for t in $THREADS; do
    for s in $SCENES; do
      for v in $VARIANTS; do
        t0=$(date +%s%N)
        threads=(--threads "$t")
        [ "$t" = - ] && threads=()
        line=$(".bin/${TRACER}_$v" render "$OUT/scenes/$s.bvh" --mode "$MODE" --res "$RES" "${threads[@]}" -o /tmp/load-frame.png 2>&1 | tail -1)
        wall=$(( ($(date +%s%N) - t0) / 1000 ))
        echo "$line" >>"$OUT/$v.log"
        frame=$(ms "$line" "measure")
        [ -n "$frame" ] || frame=$(ms "$line" "trace")
        # trace-vk prints its frame as GPU time only.
        [ -n "$frame" ] || frame=$(grep -o "[0-9.]* ms GPU" <<<"$line" | head -1 | awk '{print $1}')
        echo "$v,$s,$t,$r,$(awk -v w="$wall" 'BEGIN{print w/1000}'),$(ms "$line" "collapse"),$frame" >>"$OUT/runs.csv"
      done
    done
  done
done
rm -rf "$OUT/scenes"
{
  echo "# $TRACER render, $MODE $RES: medians over $ROUNDS rounds (range), ms"
  echo
  echo "Host: $(tr '\n' ' ' <"$OUT/host.txt")"
  echo
  echo "| scene | threads | variant | process wall | collapse | frame |"
  echo "|---|--:|---|--:|--:|--:|"
  tail -n +2 "$OUT/runs.csv" | sort -t, -k2,2 -k3,3n -k1,1 | awk -F, '
    function med(a, n,   i, j, t) { for (i = 1; i <= n; i++) for (j = i + 1; j <= n; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t }
      return (n % 2) ? a[(n + 1) / 2] : (a[n / 2] + a[n / 2 + 1]) / 2 }
    function cell(a, n) { if (a[1] == "") return "-"; return sprintf("%.1f (%.1f-%.1f)", med(a, n), a[1], a[n]) }
    function flush() { if (key != "") printf "| %s | %s | %s | %s | %s | %s |\n", s, t, v, cell(w, n), cell(c, n), cell(f, n) }
    { k = $2 "," $3 "," $1
      if (k != key) { flush(); key = k; n = 0; s = $2; t = $3; v = $1 }
      n++; w[n] = $5; c[n] = $6; f[n] = $7 }
    END { flush() }'
} >"$OUT/summary.md"
cat "$OUT/summary.md"
