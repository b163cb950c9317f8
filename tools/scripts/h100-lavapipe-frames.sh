#!/usr/bin/env bash
# Issue 9: the size axis's frames (up to 16384x16384) on lavapipe, run on the GPU machine's host CPU
# (`nvidia-h100-x2`: 32 cores; llvmpipe uses at most 32 threads) because on the 2-core VM an SST
# method alone needs about an hour for the largest frame (docs/stability.md, finding 11).
#
# Needs .lvp/ in the checkout (ignored; carried): llvm.xz (Debian 12's libLLVM-15.so.1, xz),
# rest.tar.xz (lib/: Mesa 22.3.6's libvulkan_lvp.so and the libraries it loads, from Debian 12),
# stress.xz (a stripped release `stress` of this checkout), the libvulkan1 .deb (the loader).
#
#   METHODS="GPU sst;GPU sst-subgroup" SECTION="Results: size, frames on lavapipe (32 threads), SST" \
#       OUT=... bash tools/scripts/h100-lavapipe-frames.sh
#
# METHODS: stress --method names separated by ';' (one call per group keeps a run within the
# device tool's 10 minutes). Writes $OUT/stability.md (the section) and $OUT/size-frames.{svg,png}.
set -euo pipefail
OUT=${OUT:?set OUT}
mkdir -p /tmp/lvp "$OUT"
for f in .lvp/*.deb; do dpkg -x "$f" /; done
ldconfig
tar xJf .lvp/rest.tar.xz -C /tmp/lvp
xz -dc .lvp/llvm.xz > /tmp/lvp/lib/libLLVM-15.so.1
xz -dc .lvp/stress.xz > /tmp/lvp/stress
chmod +x /tmp/lvp/stress
printf '{"file_format_version":"1.0.0","ICD":{"library_path":"/tmp/lvp/lib/libvulkan_lvp.so","api_version":"1.1.230"}}\n' > /tmp/lvp/lvp.json
export VK_DRIVER_FILES=/tmp/lvp/lvp.json LD_LIBRARY_PATH=/tmp/lvp/lib LP_NUM_THREADS=${LP_NUM_THREADS:-$(nproc)}
args=()
IFS=';' read -r -a names <<< "${METHODS:-}"
for m in "${names[@]}"; do [ -n "$m" ] && args+=(--method "$m"); done
echo "host: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2), $(nproc) cores, LP_NUM_THREADS=$LP_NUM_THREADS"
timeout "${LIMIT:-560}" /tmp/lvp/stress --axis "size: frame" --timeout 120 --max-triangles 100000 \
    --section "${SECTION:-Results: size, frames on lavapipe}" --out "$OUT/stability.md" --chart "$OUT/size-frames" \
    "${args[@]}" 2>&1 | tail -60
