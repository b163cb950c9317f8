#!/usr/bin/env bash
# The whole `bvhc compile` of million and dragon timed from outside (issue 11 item 3's 0.5 s
# target), builds of bvhc side by side: each round runs every variant once, N rounds
# (default 9), the output file removed and the disk synced before each run.
# VARIANTS: space-separated names, each picking .bin/bvhc_NAME (or .bin/bvhc_NAME.xz); a name
# ending in +t runs that binary with glibc's allocator told to keep freed memory (the tunables
# in T). R: the folder to write (ab.txt: every run with bvhc's own phases and, where
# /usr/bin/time exists, CPU times and page faults; summary.txt: each variant's times sorted;
# host.txt). Device tool: `R=$OUT VARIANTS="main new" bash tools/scripts/h100-compile-ab.sh`,
# carry [".bin"].
set -uo pipefail
R=${R:?name the output folder}; N=${N:-9}; VARIANTS=${VARIANTS:?name the variants, e.g. VARIANTS="main new"}
T=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=4294967295
for f in .bin/*.xz; do [ -e "$f" ] && xz -d "$f"; done; chmod +x .bin/*
{ nproc; grep -m1 'model name' /proc/cpuinfo; uptime; df -h /tmp | tail -1; } > $R/host.txt
TM=; [ -x /usr/bin/time ] && TM='/usr/bin/time -f %U_user_%S_sys_%R_minflt'
for s in million dragon; do
for i in $(seq 1 $N); do for v in $VARIANTS; do
  b=.bin/bvhc_${v%+t}; rm -f /tmp/o.bvh; sync; sleep 0.3
  if [ "$v" != "${v%+t}" ]; then E="GLIBC_TUNABLES=$T"; else E="X=1"; fi
  st=$(date +%s%N); env $E $TM $b compile scenes/$s.toml -o /tmp/o.bvh > /tmp/l 2>&1; en=$(date +%s%N)
  echo "$s $v $(( (en-st)/1000000 )) ms | $(tail -2 /tmp/l | tr '\n' ' ')"
done; done; done > $R/ab.txt
for s in million dragon; do for v in $VARIANTS; do echo "$s $v: $(grep "^$s $v " $R/ab.txt | awk '{print $3}' | sort -n | tr '\n' ' ')"; done; done | tee $R/summary.txt
