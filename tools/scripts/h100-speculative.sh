#!/usr/bin/env bash
# LST's speculative walk (`trace-vk bench --speculative`, lst.wgsl's SPECULATIVE trace) against
# its in-order while-while walk, side by side in each `trace-vk bench` run: rows lst+plain and
# lst+plain+speculative (plain kernels in every stage, so that the AO and diffuse stages walk
# speculatively too instead of stepping persistently). A lane that reaches a leaf walks on through
# inner nodes until its warp all hold a leaf, then the warp tests its leaves together: fewer idle
# lanes per leaf test, but more nodes and triangles per ray (on lavapipe's 8-wide subgroups 1-9%
# more nodes and 1-20% more triangles; a 32-lane warp waits longer, so likely more).
#
# What to read (summary.md): the "speculative / in order" column per row, the median of REPEATS
# runs. Above 1 on the dragon's cast row is what issue 10's 6 G/s target needs; below 1 where the
# extra nodes cost more than the idle lanes saved (expected for incoherent rays, whose lanes reach
# leaves at unrelated times).
#
# Run from the repository root on the H100 machine. Expects release binaries in .bin/:
#   .bin/trace-vk .bin/bvhc        cargo build --release -p tools   (the whilewhile branch)
# and, where .gl/ holds the Vulkan loader packages of /work/shared/device.md, unpacks them first.
# Writes $OUT (default out/h100-speculative): summary.md, one CSV and output per run. About 3
# minutes with the defaults.
#
# Env: SCENES (default dragon bunny forest), RES (default 1920x1440,7680x4320), MODES (default
# cast,whitted1,ao8,diffuse), REPEATS (default 3), FRAMES (default 15).
set -uo pipefail
OUT=${OUT:-out/h100-speculative}
SCENES=${SCENES:-dragon bunny forest}
RES=${RES:-1920x1440,7680x4320}
MODES=${MODES:-cast,whitted1,ao8,diffuse}
REPEATS=${REPEATS:-3}
FRAMES=${FRAMES:-15}
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
  echo "== run $i"
  .bin/trace-vk bench "${FILES[@]}" --cameras medium --res "$RES" --modes "$MODES" --methods lst \
    --persistent off --speculative --frames "$FRAMES" --csv "$OUT/run-$i.csv" >"$OUT/run-$i.out" 2>&1 ||
    { echo "run $i FAILED"; tail -5 "$OUT/run-$i.out"; }
done
# Columns: 1 scene, 4 width, 6 mode, 8 method, 16 mrays_per_s.
{
  echo "| scene | width | mode | in order Mrays/s | speculative Mrays/s | speculative / in order |"
  echo "|---|--:|---|--:|--:|--:|"
  for f in "$OUT"/run-*.csv; do awk -F, 'NR > 1 && $2 != "triangles"' "$f"; done |
    awk -F, '
      { k = $1 "|" $4 "|" $6; s = ($8 ~ /\+speculative$/) ? "spec" : "plain"; v[s, k] = v[s, k] " " $16; if (!(k in seen)) { seen[k] = 1; o[++n] = k } }
      function med(s,   a, c, i, j, x) { c = split(s, a, " "); for (i = 1; i <= c; i++) for (j = i + 1; j <= c; j++) if (a[j] < a[i]) { x = a[i]; a[i] = a[j]; a[j] = x }; return c % 2 ? a[(c + 1) / 2] : (a[c / 2] + a[c / 2 + 1]) / 2 }
      END { for (i = 1; i <= n; i++) { split(o[i], p, "|"); b = med(v["plain", o[i]]); a = med(v["spec", o[i]]); printf "| %s | %s | %s | %.0f | %.0f | %.3f |\n", p[1], p[2], p[3], b, a, a / b } }'
} | tee "$OUT/summary.md"
