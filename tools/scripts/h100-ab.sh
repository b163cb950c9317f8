#!/usr/bin/env bash
# Two builds of trace-vk side by side: the same `trace-vk bench` run alternated between
# .bin/trace-vk-before and .bin/trace-vk-after, REPEATS times, so that a kernel change is judged
# by a ratio measured in one session on one GPU (first used for the LST walk that carries the
# entered node, docs/measurements/h100-2026-11-25-lstcarry).
#
# Expects .bin/trace-vk-before, .bin/trace-vk-after and .bin/bvhc, release builds. Writes $OUT:
# summary.md (median Mrays/s per binary and after/before per row), the CSVs.
# Env: SCENES, RES, MODES, METHODS (default lst), PERSISTENT (default auto), REPEATS, FRAMES.
set -uo pipefail
OUT=${OUT:-out/h100-ab}
METHODS=${METHODS:-lst}
PERSISTENT=${PERSISTENT:-auto}
REPEATS=${REPEATS:-2}
FRAMES=${FRAMES:-15}
SCENES=${SCENES:-dragon forest bunny}
RES=${RES:-1920x1440,7680x4320}
MODES=${MODES:-cast,whitted1,ao8,diffuse}
mkdir -p "$OUT"
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader || true
DIR=$(mktemp -d)
FILES=()
for s in $SCENES; do
  .bin/bvhc compile "scenes/$s.toml" -o "$DIR/$s.bvh" --quiet || exit 1
  FILES+=("$DIR/$s.bvh")
done
for i in $(seq 1 "$REPEATS"); do
  for b in before after; do
    echo "== $b $i"
    ".bin/trace-vk-$b" bench "${FILES[@]}" --cameras medium --res "$RES" --modes "$MODES" --methods "$METHODS" \
      --persistent "$PERSISTENT" --frames "$FRAMES" --csv "$OUT/$b-$i.csv" >"$OUT/$b-$i.out" 2>&1 || { echo "$b $i FAILED"; tail -5 "$OUT/$b-$i.out"; }
  done
done
# Columns: 1 scene, 4 width, 6 mode, 8 method, 16 mrays_per_s.
{
  echo "| scene | width | mode | method | before Mrays/s | after Mrays/s | after / before |"
  echo "|---|--:|---|---|--:|--:|--:|"
  for b in before after; do for f in "$OUT"/$b-*.csv; do awk -F, -v b=$b 'NR > 1 && $2 != "triangles" { print b "," $0 }' "$f"; done; done |
    awk -F, '
      { k = $2 "|" $5 "|" $7 "|" $9; v[$1, k] = v[$1, k] " " $17; if (!(k in seen)) { seen[k] = 1; o[++n] = k } }
      function med(s,   a, c, i, j, x) { c = split(s, a, " "); for (i = 1; i <= c; i++) for (j = i + 1; j <= c; j++) if (a[j] < a[i]) { x = a[i]; a[i] = a[j]; a[j] = x }; return c % 2 ? a[(c + 1) / 2] : (a[c / 2] + a[c / 2 + 1]) / 2 }
      END { for (i = 1; i <= n; i++) { split(o[i], p, "|"); b = med(v["before", o[i]]); a = med(v["after", o[i]]); printf "| %s | %s | %s | %s | %.0f | %.0f | %.3f |\n", p[1], p[2], p[3], p[4], b, a, a / b } }'
} | tee "$OUT/summary.md"
