#!/usr/bin/env bash
# Issue 11 item 3's builder figures on the H100 machine's 16-core host (docs/build-benchmark.md):
# 16 bins against the `bvh` crate on 2 threads and on all threads (bunny, dragon, million), this
# build side by side with the build before it when its binary is carried; every builder on all
# threads; 16 and 64 bins against the full sweep on the scenes beyond the benchmark; where the
# time of `bvhc compile` goes; and the whole `bvhc compile` of million, dragon and bunny, timed
# from outside.
#
# Run from the repository root on the device machine. The host has no Rust toolchain: build the
# release binaries here and carry .bin/ (ignored; about 25 MiB in all):
#   cargo build --release -p bvh-build --features compare --example build_report --example compile_profile
#   cargo build --release -p bvh-build --example build_cpu
#   cargo build --release -p tools --bin bvhc
#   mkdir -p .bin && cp target/release/examples/build_report target/release/examples/compile_profile \
#     target/release/examples/build_cpu target/release/bvhc .bin/ && strip .bin/*
# (.bin/build_cpu is optional: without it the thread-scaling section, scaling.txt, is skipped.)
# Optionally the build to compare with (before.md, two-before.md), from a worktree of main before
# the change: `cargo build --release -p bvh-build --features compare --example build_report --example build_cpu`
# there, and its binaries copied to .bin/build_report_before and .bin/build_cpu_before (the
# latter: scaling.txt runs both, alternately).
# The scenes are tracked files under scenes/ (million.toml places dragon.glb and two bunny.glb,
# 17 MiB), so the working tree carries them; the one generated on the host is room_big.toml, the
# room with its glass sphere at 1024 x 512 segments (1,047,514 triangles), into $OUT.
# Device tool: command `bash tools/scripts/h100-build.sh`, carry [".bin", ".gl"] (.gl/eval: the
# fontconfig packages build_report needs). Writes into $OUT
# (default ./out/h100-build): two.md (2 threads: 16 bins and bvh), two-before.md (the same with
# the earlier build), build.md (all threads, every builder), before.md (all threads, 16 bins and
# bvh with the earlier build), others.md (16 and 64 bins and the sweep on the other scenes),
# others-before.md (the same with the earlier build: its sweep is the plain greedy one, without
# the reinsertion in the top), scaling.txt (build_cpu --phases at 1 to 16 threads: wall and CPU
# time and the wall time of each phase of the build), profile.txt, phases.txt, compile.txt,
# host.txt, log.txt. At the end everything but log.txt is packed into $OUT/h100-build.tgz (the
# device tool returns few files): `tar xzf h100-build.tgz` to unpack.
# Expected run time: about 6 minutes with RUNS=7 (the full sweep of million and forest, a second
# or two per build, is a third of it); RUNS=5 for a shorter run.
set -euo pipefail
OUT=${OUT:-out/h100-build}
RUNS=${RUNS:-7}
mkdir -p "$OUT"
for b in build_report compile_profile bvhc; do
  [ -x ".bin/$b" ] || { echo "missing .bin/$b (see the top of $0)" >&2; exit 1; }
done
export BVH_SCENES_DIR=$PWD/scenes
# build_report links fontconfig for its chart (plotters): the host has none, so unpack the
# packages of .gl/eval (libfontconfig1 and what it needs, as ../shared/device.md fetches them).
if [ -d .gl/eval ]; then
  for f in .gl/eval/*.deb; do dpkg -x "$f" /; done
  ldconfig
fi
{
  echo "host: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ //')"
  echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
  # The build advises its large buffers to huge pages (bvh-build/src/build.rs): with `always` the
  # earlier build had them too, with `never` neither has.
  echo "transparent huge pages: $(cat /sys/kernel/mm/transparent_hugepage/enabled 2>/dev/null || echo unknown)"
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC'); git: $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
} | tee "$OUT/host.txt"
exec > >(tee "$OUT/log.txt") 2>&1
START=$(date +%s)
log() { echo "[$(($(date +%s) - START)) s] $*"; }

# 16 bins and bvh on bunny, dragon, million; each report prints its table and the targets.
pair() { # threads binary out-name
  mkdir -p "$OUT/$3"
  RAYON_NUM_THREADS=$1 ".bin/$2" --runs "$RUNS" --scenes bunny,dragon,million --builders binned16,bvh \
    --out "$OUT/$3" 2>/dev/null | grep -E '^\||^- '
  cp "$OUT/$3/build-benchmark.md" "$OUT/$3.md"
}
log "== 2 threads: 16 bins against bvh (this build) =="
pair 2 build_report two
if [ -x .bin/build_report_before ]; then
  log "== 2 threads: 16 bins against bvh (the earlier build) =="
  pair 2 build_report_before two-before
  log "== all $(nproc) threads: 16 bins against bvh (the earlier build) =="
  pair "$(nproc)" build_report_before before
fi

log "== all $(nproc) threads, every builder: bunny, dragon, million =="
mkdir -p "$OUT/all"
.bin/build_report --runs "$RUNS" --scenes bunny,dragon,million \
  --builders binned4,binned8,binned16,binned32,binned64,sweep,bvh,obvhs --out "$OUT/all" 2>/dev/null | grep -E '^\||^- '
cp "$OUT/all/build-benchmark.md" "$OUT/build.md"

log "== 16 and 64 bins against the sweep on the scenes beyond the benchmark (all threads) =="
sed 's/segments = 48/segments = 1024/; s/rings = 24/rings = 512/' scenes/room.toml >"$OUT/room_big.toml"
OTHERS=scenes/toycar.glb,scenes/car.toml,scenes/forest.toml,scenes/room.toml,$OUT/room_big.toml
mkdir -p "$OUT/others"
.bin/build_report --runs 3 --builders binned16,binned64,sweep --scenes "$OTHERS" --out "$OUT/others" 2>/dev/null |
  grep -E '^\||^- '
cp "$OUT/others/build-benchmark.md" "$OUT/others.md"
if [ -x .bin/build_report_before ]; then
  log "== the same with the earlier build =="
  mkdir -p "$OUT/others-before"
  .bin/build_report_before --runs 3 --builders binned16,binned64,sweep --scenes "$OTHERS" --out "$OUT/others-before" \
    2>/dev/null | grep -E '^\||^- '
  cp "$OUT/others-before/build-benchmark.md" "$OUT/others-before.md"
fi

if [ -x .bin/build_cpu ]; then
  log "== build time against threads: wall and CPU time of all threads, wall time per phase (medians of 15 builds) =="
  # Where the small scene stops scaling: CPU time far above the 1-thread figure means threads
  # spinning or waiting (rayon, page faults), wall time flat while CPU time stays means serial
  # parts; the phase line says which (setup, the top's parallel splits and the rest of the
  # recursion, the reinsertion, the layouts, freeing the buffers). With .bin/build_cpu_before,
  # the earlier build's line (no phases) before each of this build's, alternately.
  for s in bunny.toml million.toml; do
    for threads in 1 2 4 8 16 "$(nproc)"; do
      if [ -x .bin/build_cpu_before ]; then
        echo -n "before: "
        RAYON_NUM_THREADS=$threads .bin/build_cpu_before "scenes/$s" 15
      fi
      RAYON_NUM_THREADS=$threads .bin/build_cpu "scenes/$s" 15 --phases
    done
  done | tee "$OUT/scaling.txt"
fi

log "== where the time of bvhc compile goes (medians of $RUNS) =="
for s in million.toml dragon.toml bunny.toml; do
  .bin/compile_profile "scenes/$s" --runs "$RUNS"
done | tee "$OUT/profile.txt"

log "== bvhc compile million.toml, its own phases on all $(nproc) threads (medians of $RUNS) =="
# bvhc's second output line: "  import I s, build B s (binned 16 bins), write W s".
for _ in $(seq "$RUNS"); do
  .bin/bvhc compile scenes/million.toml -o "$OUT/scene.bvh" | sed -n 's/.*import \([0-9.]*\) s, build \([0-9.]*\) s.*write \([0-9.]*\) s.*/\1 \2 \3/p'
done > "$OUT/phases.raw"
for k in 1 2 3; do
  name=$(echo "import build write" | cut -d' ' -f"$k")
  echo "bvhc phase $name: median $(cut -d' ' -f"$k" "$OUT/phases.raw" | sort -n | sed -n "$(((RUNS + 1) / 2))p") s (all: $(cut -d' ' -f"$k" "$OUT/phases.raw" | sort -n | tr '\n' ' '))"
done | tee "$OUT/phases.txt"

log "== bvhc compile, whole command timed from outside (medians of $RUNS; all threads, then 2) =="
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
log "done"
# One archive of every output but the log (the device tool returns a limited number of files).
tar czf /tmp/h100-build.tgz -C "$OUT" --exclude=log.txt .
find "$OUT" -mindepth 1 -maxdepth 1 ! -name log.txt -exec rm -rf {} +
mv /tmp/h100-build.tgz "$OUT/h100-build.tgz"
