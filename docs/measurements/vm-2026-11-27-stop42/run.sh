cd /work/main
for r in 1 2; do for v in main final; do
  echo "== $v $r $(date -u +%H:%M:%S) load $(cut -d' ' -f1 /proc/loadavg)"
  /tmp/rr_$v --scene bunny=scenes/bunny.toml --scene dragon=scenes/dragon.toml --scene million=scenes/million.toml --sizes 640x480 --threads 1,2 --reps 5 --engines "ours bvh8,ours bvh8 packet,Embree 1,Embree 1 robust,Embree 8,Embree 8 robust" --out /tmp/vm42/$v-$r.md > /dev/null 2>/tmp/vm42/$v-$r.log
done; done
echo done $(date -u +%H:%M:%S)
