#!/usr/bin/env bash
# Issue 8 item 2, `--exact` on an NVIDIA GPU (made for the H100 machine): are trace-vk's Whitted
# images equal to trace-cpu's bit for bit on every shipped scene with --exact, how many pixels
# differ without it, and what --exact costs in `trace-vk bench`. About 5 minutes.
#
# Run from the repository root. Expects release binaries in .bin/ (built on the development
# machine: they link only libc, libm and libgcc_s):
#   .bin/trace-vk .bin/trace-cpu .bin/bvhc     cargo build --release -p tools
#   .bin/image_diff                            cargo build --release -p tools --example image_diff
#   .bin/tracer-vk-tests (optional)            the binary `cargo test --release -p tracer-vk --lib
#                                              --no-run` names (target/release/deps/tracer_vk-*)
#   .bin/wgsl-functions-tests (optional)       the binary `cargo test --release -p tests --test
#                                              wgsl_functions --no-run` names
#   .bin/exact-rounding-tests (optional)        the binary `cargo test --release -p tracer-vk --test
#                                              exact_rounding --no-run` names (div_rn, sqrt_rn)
# and, where .gl/ holds the Vulkan loader packages of /work/shared/device.md, unpacks them first.
# Writes $OUT (default out/h100-exact): summary.md (read this), log.txt, bench.tgz (the CSV and
# Markdown tables) and differing.tgz (the images of every comparison that differs under --exact).
#
# Env: RES (default 640x480), METHODS (default lst,stackless,sst,sst-subgroup), CAMERAS (default:
# each scene's first camera; e.g. "medium close-up wide"), BENCH_RES (default 1280x960), FRAMES
# (default 20), ROUNDS (bench rounds alternating plain and exact, default 2).
set -euo pipefail
OUT=${OUT:-out/h100-exact}
RES=${RES:-640x480}
METHODS=${METHODS:-lst,stackless,sst,sst-subgroup}
CAMERAS=${CAMERAS:-}
BENCH_RES=${BENCH_RES:-1280x960}
FRAMES=${FRAMES:-20}
ROUNDS=${ROUNDS:-2}
BIN=.bin
WORK=$(mktemp -d)
mkdir -p "$OUT" "$WORK/scenes" "$WORK/img" "$WORK/differing" "$WORK/bench"
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*" | tee -a "$OUT/log.txt" >&2; }

for b in trace-cpu trace-vk bvhc image_diff; do
  [ -x "$BIN/$b" ] || { echo "missing $BIN/$b (see the top of $0)" >&2; exit 1; }
done
if [ -d .gl ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
  # The validation layer the test binaries turn on, used on their command lines only.
  if [ -d .gl/tools ]; then mkdir -p /tmp/vt; for f in .gl/tools/*.deb; do dpkg -x "$f" /tmp/vt; done; fi
fi

# Every shipped scene, compiled once; "default" is the built-in bunny (no scene argument).
SCENES=(default)
for t in scenes/*.toml; do
  n=$(basename "$t" .toml)
  log "bvhc compile $t"
  "$BIN/bvhc" compile "$t" -o "$WORK/scenes/$n.bvh" >>"$OUT/log.txt" 2>&1
  SCENES+=("$n")
done
scene_arg() { [ "$1" = default ] || echo "$WORK/scenes/$1.bvh"; }

{
  echo "# --exact on $("$BIN/trace-vk" devices 2>/dev/null | head -1 | cut -d'(' -f1 | sed 's/^[0-9]*: //')"
  echo
  echo "- Date: $(date -u '+%Y-%m-%d %H:%M UTC'); host $(hostname), $(nproc) cores; script tools/scripts/h100-exact.sh; git $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
  echo "- Devices: $("$BIN/trace-vk" devices 2>&1 | tr '\n' ' ')"
  echo
  echo "## Whitted images, $RES: trace-vk against trace-cpu, pixel by pixel"
  echo
  echo "Pixels whose 8-bit colour differs from trace-cpu's, without and with --exact (of $(( ${RES%x*} * ${RES#*x} )) per image); max = largest channel difference in 1/255 steps."
  echo
  echo "| scene | camera | method | plain: different (max) | --exact: different (max) |"
  echo "|---|---|---|---:|---:|"
} >"$OUT/summary.md"

exact_total=0
plain_total=0
images=0
for s in "${SCENES[@]}"; do
  arg=$(scene_arg "$s")
  cams=${CAMERAS:-first}
  for cam in $cams; do
    camopt=()
    [ "$cam" = first ] || camopt=(--camera "$cam")
    base="$WORK/img/$s-$cam"
    # shellcheck disable=SC2086
    if ! "$BIN/trace-cpu" render $arg "${camopt[@]}" --mode whitted --res "$RES" -o "$base-cpu.png" >>"$OUT/log.txt" 2>&1; then
      log "trace-cpu failed on $s $cam (see log.txt)"
      echo "| $s | $cam | - | trace-cpu failed | |" >>"$OUT/summary.md"
      continue
    fi
    for m in ${METHODS//,/ }; do
      row="| $s | $cam | $m |"
      for variant in plain exact; do
        flag=()
        [ "$variant" = exact ] && flag=(--exact)
        img="$base-$m-$variant.png"
        # shellcheck disable=SC2086
        if "$BIN/trace-vk" render $arg "${camopt[@]}" --mode whitted --res "$RES" --method "$m" "${flag[@]}" -o "$img" >>"$OUT/log.txt" 2>&1; then
          read -r _ same _ diff _ max < <("$BIN/image_diff" "$base-cpu.png" "$img")
          row="$row $diff ($max) |"
          if [ "$variant" = exact ]; then
            exact_total=$((exact_total + diff))
            images=$((images + 1))
            [ "$diff" = 0 ] || cp "$base-cpu.png" "$img" "$WORK/differing/"
          else
            plain_total=$((plain_total + diff))
          fi
        else
          row="$row failed |"
          log "trace-vk $variant failed on $s $cam $m (see log.txt)"
        fi
      done
      echo "$row" >>"$OUT/summary.md"
      log "$row"
    done
  done
done
{
  echo
  echo "**In all: $plain_total pixels differ without --exact, $exact_total with --exact, over $images image pairs.**"
  echo
} >>"$OUT/summary.md"

# The pass's own device tests: a * b + c with and without NoContraction on inputs where a fused
# multiply-add rounds differently (tracer-vk/src/no_contraction.rs), and every shared WGSL function
# against its Rust twin, bit for bit, without and with the pass (tests/tests/wgsl_functions.rs).
with_layer() {
  if [ -d /tmp/vt ]; then
    env LD_LIBRARY_PATH=/tmp/vt/usr/lib/x86_64-linux-gnu VK_LAYER_PATH=/tmp/vt/usr/share/vulkan/explicit_layer.d "$@"
  else
    "$@"
  fi
}
for t in tracer-vk-tests:no_contraction wgsl-functions-tests:every_shared exact-rounding-tests:the_wgsl; do
  b=${t%%:*}
  [ -x "$BIN/$b" ] || continue
  log "$b ${t#*:}"
  {
    echo "## $b ${t#*:} on this device"
    echo
    echo '```'
    with_layer "$BIN/$b" "${t#*:}" --nocapture --test-threads 1 2>&1 | grep -E 'differ|cases|^test |test result|panicked' | cut -c1-400 | head -20 || true
    echo '```'
    echo
  } >>"$OUT/summary.md"
done

# The cost: trace-vk bench, plain and exact alternating, the same matrix.
BENCH_SCENES=()
for s in "${SCENES[@]}"; do [ "$s" = default ] || BENCH_SCENES+=("$WORK/scenes/$s.bvh"); done
A=(--cameras medium --res "$BENCH_RES" --modes cast,whitted1 --methods "$METHODS" --frames "$FRAMES")
for r in $(seq "$ROUNDS"); do
  for variant in plain exact; do
    flag=()
    [ "$variant" = exact ] && flag=(--exact)
    log "trace-vk bench round $r $variant"
    timeout 300 "$BIN/trace-vk" bench "${BENCH_SCENES[@]}" "${A[@]}" "${flag[@]}" \
      --csv "$WORK/bench/$variant$r.csv" >>"$OUT/log.txt" 2>&1 || log "bench $variant $r failed"
  done
done
{
  echo "## The cost of --exact: trace-vk bench, medium camera, $BENCH_RES, median of $FRAMES frames"
  echo
  echo "Milliseconds per frame (GPU timestamps), each round's plain run followed by its exact run; ratio = exact / plain of the medians over rounds."
  echo
  echo "| scene | mode | method | plain ms (rounds) | exact ms (rounds) | exact / plain |"
  echo "|---|---|---|---|---|---:|"
  # CSV columns: scene,triangles,camera,width,height,mode,lights,method,median_ms,...
  awk -F, -v rounds="$ROUNDS" '
    FNR == 1 { split(FILENAME, p, "/"); f = p[length(p)]; v = (f ~ /^exact/) ? "exact" : "plain"; next }
    { k = $1 "|" $6 "|" $8; if (!(k in seen)) { seen[k] = 1; order[++n] = k }
      ms[k, v] = ms[k, v] (ms[k, v] == "" ? "" : " ") $9; cnt[k, v]++; val[k, v, cnt[k, v]] = $9 }
    function med(k, v,   i, j, t, c, a) {
      c = cnt[k, v]; if (c == 0) return 0
      for (i = 1; i <= c; i++) a[i] = val[k, v, i]
      for (i = 1; i <= c; i++) for (j = i + 1; j <= c; j++) if (a[j] < a[i]) { t = a[i]; a[i] = a[j]; a[j] = t }
      return (c % 2) ? a[(c + 1) / 2] : (a[c / 2] + a[c / 2 + 1]) / 2 }
    END { for (i = 1; i <= n; i++) { k = order[i]; split(k, col, "|"); pm = med(k, "plain"); em = med(k, "exact")
      printf "| %s | %s | %s | %s | %s | %s |\n", col[1], col[2], col[3], ms[k, "plain"], ms[k, "exact"], (pm > 0 ? sprintf("%.3f", em / pm) : "-") } }
  ' "$WORK"/bench/*.csv 2>>"$OUT/log.txt" | sed 's#[^|]*/scenes/\([a-z]*\)\.bvh#\1#'
  echo
  echo "- $(($(date +%s) - START)) s in all"
} >>"$OUT/summary.md"

tar czf "$OUT/bench.tgz" -C "$WORK" bench
if [ -n "$(ls -A "$WORK/differing")" ]; then tar czf "$OUT/differing.tgz" -C "$WORK" differing; fi
rm -rf "$WORK"
log "done: $OUT/summary.md"
cat "$OUT/summary.md"
