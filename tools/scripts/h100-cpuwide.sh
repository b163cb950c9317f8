#!/usr/bin/env bash
# Issue 11 items 1 and 2 on the H100 machine's 16-core host: the ray report (ours beside Embree 3,
# the same rays on the same triangles) on bunny, dragon and million at 640x480 and 1920x1440, 1 and
# all threads, primary, shadow, secondary, AO and diffuse rays: the wide BVH one ray at a time
# ("ours bvh8") against rtcIntersect1/rtcOccluded1 with Embree's default and robust flags, and our
# packets against rtcIntersect8/rtcOccluded8; plus `trace-cpu render --method auto` against its
# fixed methods on the dragon.
#
# Run from the repository root on the device machine. The host has no Rust toolchain nor Embree:
# build here (Debian 12 with libembree-dev) and carry .bin/ (ignored):
#   cargo build --release -p tracer-cpu --features embree --example ray_report
#   cargo build --release -p tools --bin trace-cpu --bin bvhc
#   mkdir -p .bin && cp target/release/examples/ray_report target/release/trace-cpu target/release/bvhc .bin/ \
#     && strip .bin/ray_report .bin/trace-cpu .bin/bvhc
#   (cd /tmp && apt-get download libembree3-3 libtbb12 libtbbmalloc2) && for d in /tmp/lib*.deb; do dpkg -x "$d" .bin/embree; done
# (.bin/embree/usr/lib/x86_64-linux-gnu then holds libembree3.so.3 and libtbb.so.12; a caller that
# sets LD_LIBRARY_PATH to its own copy may leave .bin/embree out.) The scenes are the tracked
# files under scenes/.
# Device tool: command `bash tools/scripts/h100-cpuwide.sh`, carry [".bin"]. Writes into $OUT
# (default ./out/h100-cpuwide): ray-report.md (the report's markdown: issue 11's ratios first,
# then Mrays/s and hit agreement), auto.md (trace-cpu render timing lines), host.txt, log.txt.
# Expected run time: about 6 minutes (the ray report's one-thread passes over the 1920x1440 sets
# of dragon and million are most of it).
set -euo pipefail
OUT=${OUT:-out/h100-cpuwide}
mkdir -p "$OUT"
for b in ray_report trace-cpu bvhc; do
  [ -x ".bin/$b" ] || { echo "missing .bin/$b (see the top of $0)" >&2; exit 1; }
done
if [ -d .bin/embree/usr/lib/x86_64-linux-gnu ]; then
  export LD_LIBRARY_PATH=$PWD/.bin/embree/usr/lib/x86_64-linux-gnu${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
fi
if ldd .bin/ray_report | grep -q 'not found'; then
  echo "ray_report cannot find its libraries (Embree 3 and TBB; see the top of $0):" >&2
  ldd .bin/ray_report | grep 'not found' >&2
  exit 1
fi
ALL=$(nproc)
{
  echo "host: $ALL cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "flags: $(grep -m1 '^flags' /proc/cpuinfo | tr ' ' '\n' | grep -E '^(avx2|fma|avx512f|avx512vl)$' | tr '\n' ' ')"
  echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC'); git: $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
} | tee "$OUT/host.txt"
exec > >(tee "$OUT/log.txt") 2>&1

echo "== ray report: bunny, dragon, million; 640x480 and 1920x1440; 1 and $ALL threads =="
.bin/ray_report --threads "1,$ALL" --reps 3 --out "$OUT/ray-report.md" >/dev/null

echo "== trace-cpu render --method auto against the fixed methods: dragon 1920x1440, $ALL threads (3 runs each) =="
.bin/bvhc compile scenes/dragon.toml -o "$OUT/dragon.bvh" >/dev/null
{
  echo "# trace-cpu render, dragon 1920x1440, camera medium, $ALL threads: timing lines, 3 runs per method"
  echo
  for mode in cast whitted ao diffuse; do
    for run in 1 2 3; do
      for m in auto bvh8 packet ordered; do
        echo "- $mode $m: $(.bin/trace-cpu render "$OUT/dragon.bvh" --mode "$mode" --res 1920x1440 --method "$m" \
          -o "$OUT/dragon.png" 2>&1 | head -1)"
      done
    done
  done
} >"$OUT/auto.md"
rm -f "$OUT/dragon.png" "$OUT/dragon.bvh"
echo "done: $OUT/ray-report.md, $OUT/auto.md"
