#!/usr/bin/env bash
# Issue 8's speed-against-accuracy figures on the H100 machine (docs/accuracy.md): `trace-eval`
# on four shipped scenes at 640x480, Whitted with one light, every accuracy setting (each alone
# against the defaults), the GPU's three traversals and rt-pipeline with and without --exact, and the CPU tracer
# on the host's 16 cores, against the f64 reference at 64 samples per pixel.
#
# Run from the repository root, on the device machine, after the Vulkan loader set-up of
# /work/shared/device.md ("Running on the H100 through the device tool": unpack .gl/*.deb into /,
# ldconfig, VK_DRIVER_FILES). Expects a release binary in .bin/ and the scenes in scenes/ (the
# working tree carries them):
#   .bin/trace-eval     cargo build --release -p tools && cp target/release/trace-eval .bin/
# trace-eval alone (not the tracers) links fontconfig and FreeType for its charts' text and
# libstdc++ for FLIP. Where the GPU machine lacks them, carry them like the Vulkan loader, in
# .gl/eval/ (downloaded here with the `o=...` options of device.md):
#   (mkdir -p .gl/eval && cd .gl/eval && apt-get $o download libfontconfig1 fontconfig-config \
#     fonts-dejavu-core libfreetype6 libpng16-16 libbrotli1 libexpat1)
# and this script unpacks them when `ldd` finds a library missing.
# Writes everything into $OUT (default ./out/h100-eval): eval.csv, eval.md, a chart per scene
# (SVG, PNG), the reference cache, host.txt and log.txt. Expected run time on the H100 host:
# about 4 to 6 minutes (most of it the f64 references and the CPU's 16-sample frames of the
# million-triangle scenes); well within the device tool's 10 minutes.
set -euo pipefail
OUT=${OUT:-out/h100-eval}
# RES and SCENES only shrink a trial run on a small machine.
RES=${RES:-640x480}
SCENES=${SCENES:-scenes/bunny.toml scenes/dragon.toml scenes/car.toml scenes/forest.toml}
mkdir -p "$OUT"
[ -x .bin/trace-eval ] || { echo "missing .bin/trace-eval (see the top of $0)" >&2; exit 1; }
if ldd .bin/trace-eval | grep -q 'not found'; then
  for f in .gl/eval/*.deb; do dpkg -x "$f" /; done
  ldconfig
  ldd .bin/trace-eval | grep 'not found' && { echo "trace-eval still misses libraries (see the top of $0)" >&2; exit 1; }
fi
{
  echo "host: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  nvidia-smi -L 2>&1 || true
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC'); git: $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
} > "$OUT/host.txt"
START=$(date +%s)
# shellcheck disable=SC2086 # SCENES is a list of paths
.bin/trace-eval $SCENES --cameras medium --res "$RES" --modes whitted1 \
  --cpu-methods auto --gpu-methods lst,stackless,sst,rt-pipeline \
  --intersect watertight,mt --offset scale,1e-4,1e-3,1e-2 --spp 1,4,16 --cutoff default,0 --exact off,on \
  --reference-spp 64 --out "$OUT" 2>&1 | tee "$OUT/log.txt"
echo "eval took $(($(date +%s) - START)) s" | tee -a "$OUT/log.txt"
ls -la "$OUT"
