#!/bin/bash
# Resident memory while tracing: VmRSS of trace-cpu render sampled every 0.02 s from start to
# exit; the median sample (the frame's tracing is most of the run, the load's peak and the exit
# are short) and the peak (VmHWM).
B=/work/wt/cwbvh/target/release/trace-cpu
for s in dragon million; do for m in ordered packet bvh8 auto; do for r in 1 2 3; do for v in expanded indexed; do
  $B render $s.bvh --method $m --vertices $v --res 1920x1440 --mode whitted -o /tmp/cvm/o3.png >/tmp/cvm/last3.txt 2>&1 &
  pid=$!; samples=(); hwm=0
  while kill -0 $pid 2>/dev/null; do
    x=$(awk '/VmRSS/{print $2}' /proc/$pid/status 2>/dev/null); [ -n "$x" ] && samples+=($x)
    y=$(awk '/VmHWM/{print $2}' /proc/$pid/status 2>/dev/null); [ -n "$y" ] && hwm=$y
    sleep 0.02
  done
  wait $pid
  med=$(printf '%s\n' "${samples[@]}" | sort -n | awk '{a[NR]=$1} END{print a[int((NR+1)/2)]}')
  held=$(grep -o "holds [0-9]* bytes" /tmp/cvm/last3.txt | cut -d' ' -f2)
  echo "$s $m $v $r $med $hwm ${#samples[@]} $held"
done; done; done; done
