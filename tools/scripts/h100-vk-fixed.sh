#!/usr/bin/env bash
# What a `trace-vk` process costs besides its frame, on the device machine: each command 5 times,
# wall time from outside (ms): `devices` (the loader, the instance and the devices' listing), and
# `render --method lst --mode cast` of the bunny and the dragon at 16x16 (what every render pays
# whatever its size) and at 1920x1440 (PNG and BMP), auto's pick, a 16x16 Whitted frame.
# Usage: bash tools/scripts/h100-vk-fixed.sh OUTDIR, from the repository root, carrying .gl (the
# Vulkan loader's packages, ../shared/device.md) and .bin with trace-vk.xz and bvhc.xz. Writes
# OUTDIR/times.csv (name, round, ms), lines.txt (each command's last output line), devices.txt.
set -uo pipefail
R=$1; for f in .gl/*.deb; do dpkg -x $f /; done; ldconfig; export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
xz -d .bin/*.xz; chmod +x .bin/*; mkdir -p /tmp/sc
for s in bunny dragon; do .bin/bvhc compile scenes/$s.toml -o /tmp/sc/$s.bvh > /dev/null; done
t() { local name=$1 s; shift; for i in 1 2 3 4 5; do s=$(date +%s%N); "$@" > /tmp/last.txt 2>&1; echo "$name,$i,$(( ($(date +%s%N)-s)/1000000 ))"; done; tail -1 /tmp/last.txt | cut -c1-200 >> $R/lines.txt; }
{
t devices .bin/trace-vk devices
t bunny-lst-16x16 .bin/trace-vk render /tmp/sc/bunny.bvh --method lst --mode cast --res 16x16 -o /tmp/x.png
t bunny-lst-1920 .bin/trace-vk render /tmp/sc/bunny.bvh --method lst --mode cast --res 1920x1440 -o /tmp/x.png
t bunny-lst-1920-bmp .bin/trace-vk render /tmp/sc/bunny.bvh --method lst --mode cast --res 1920x1440 -o /tmp/x.bmp
t bunny-auto-1920 .bin/trace-vk render /tmp/sc/bunny.bvh --mode cast --res 1920x1440 -o /tmp/x.png
t dragon-lst-16x16 .bin/trace-vk render /tmp/sc/dragon.bvh --method lst --mode cast --res 16x16 -o /tmp/x.png
t dragon-lst-1920 .bin/trace-vk render /tmp/sc/dragon.bvh --method lst --mode cast --res 1920x1440 -o /tmp/x.png
t bunny-whitted-16x16 .bin/trace-vk render /tmp/sc/bunny.bvh --method lst --mode whitted --res 16x16 -o /tmp/x.png
} > $R/times.csv
.bin/trace-vk devices > $R/devices.txt 2>&1
