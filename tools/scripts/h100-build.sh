#!/usr/bin/env bash
# Issue 11 item 3's builder figures on the H100 machine's 16-core host (docs/build-benchmark.md):
# build time of a million triangles on all threads and on 2, against the `bvh` crate and obvhs;
# 16 bins against the full sweep on the benchmark scenes and on the others; where the time of
# `bvhc compile` goes; and the whole `bvhc compile` (import, build, write, fsync) of million,
# dragon and bunny, timed from outside.
#
# Run from the repository root on the device machine. The host has no Rust toolchain: build the
# release binaries here and carry .bin/ (ignored; about 20 MiB in all):
#   cargo build --release -p bvh-build --features compare --example build_report --example compile_profile
#   cargo build --release -p tools --bin bvhc
#   mkdir -p .bin && cp target/release/examples/build_report target/release/examples/compile_profile \
#     target/release/bvhc .bin/ && strip .bin/*
# The scenes are tracked files under scenes/ (million.toml places dragon.glb and two bunny.glb,
# 17 MiB), so the working tree carries them; nothing is generated on the host.
# Device tool: command `bash tools/scripts/h100-build.sh`, carry [".bin"]. Writes build.md
# (build_report's tables), others.md, profile.txt, phases.txt, compile.txt, host.txt and log.txt into $OUT
# (default ./out/h100-build). Expected run time: about 3 minutes (the full sweep of million and
# forest, a few seconds per build, is most of it).
set -euo pipefail
OUT=${OUT:-out/h100-build}
RUNS=${RUNS:-7}
mkdir -p "$OUT"
for b in build_report compile_profile bvhc; do
  [ -x ".bin/$b" ] || { echo "missing .bin/$b (see the top of $0)" >&2; exit 1; }
done
export BVH_SCENES_DIR=$PWD/scenes
{
  echo "host: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC'); git: $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
} | tee "$OUT/host.txt"
exec > >(tee "$OUT/log.txt") 2>&1

echo "== build time, all $(nproc) threads: bunny, dragon, million (16 bins, sweep, bvh, obvhs) =="
mkdir -p "$OUT/all"
.bin/build_report --runs "$RUNS" --scenes bunny,dragon,million \
  --builders binned4,binned8,binned16,binned32,binned64,sweep,bvh,obvhs --out "$OUT/all" 2>/dev/null
cp "$OUT/all/build-benchmark.md" "$OUT/build.md"

echo "== build time, 2 threads (16 bins against bvh) =="
mkdir -p "$OUT/two"
RAYON_NUM_THREADS=2 .bin/build_report --runs "$RUNS" --scenes bunny,dragon,million \
  --builders binned16,bvh --out "$OUT/two" 2>/dev/null

echo "== 16 bins against the sweep on the scenes beyond the benchmark (all threads) =="
mkdir -p "$OUT/others"
.bin/build_report --runs 3 --builders binned16,binned64,sweep \
  --scenes scenes/toycar.glb,scenes/car.toml,scenes/forest.toml,scenes/room.toml --out "$OUT/others" 2>/dev/null
cp "$OUT/others/build-benchmark.md" "$OUT/others.md"

echo "== where the time of bvhc compile goes (medians of $RUNS) =="
for s in million.toml dragon.toml bunny.toml; do
  .bin/compile_profile "scenes/$s" --runs "$RUNS"
done | tee "$OUT/profile.txt"

echo "== bvhc compile million.toml, its own phases on all $(nproc) threads (medians of $RUNS) =="
# bvhc's second output line: "  import I s, build B s (binned 16 bins), write W s".
for _ in $(seq "$RUNS"); do
  .bin/bvhc compile scenes/million.toml -o "$OUT/scene.bvh" | sed -n 's/.*import \([0-9.]*\) s, build \([0-9.]*\) s.*write \([0-9.]*\) s.*/\1 \2 \3/p'
done > "$OUT/phases.raw"
for k in 1 2 3; do
  name=$(echo "import build write" | cut -d' ' -f"$k")
  echo "bvhc phase $name: median $(cut -d' ' -f"$k" "$OUT/phases.raw" | sort -n | sed -n "$(((RUNS + 1) / 2))p") s (all: $(cut -d' ' -f"$k" "$OUT/phases.raw" | sort -n | tr '\n' ' '))"
done | tee "$OUT/phases.txt"

echo "== bvhc compile, whole command timed from outside (medians of $RUNS; 16 threads, then 2) =="
for threads in "$(nproc)" 2; do
  for s in million.toml dragon.toml bunny.toml; do
    times=()
    for _ in $(seq "$RUNS"); do
      t0=$(date +%s%N)
      RAYON_NUM_THREADS=$threads .bin/bvhc compile "scenes/$s" -o "$OUT/scene.bvh" --quiet
      times+=($((($(date +%s%N) - t0) / 1000000)))
    done
    sorted=$(printf '%s\n' "${times[@]}" | sort -n | tr '\n' ' ')
    median=$(printf '%s\n' "${times[@]}" | sort -n | sed -n "$(((RUNS + 1) / 2))p")
    echo "bvhc compile $s, $threads threads: median $median ms (all: $sorted)"
  done
  RAYON_NUM_THREADS=$threads .bin/bvhc compile scenes/million.toml -o "$OUT/scene.bvh"
done | tee "$OUT/compile.txt"
rm -f "$OUT/scene.bvh"
