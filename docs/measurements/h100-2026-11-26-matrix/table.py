#!/usr/bin/env python3
# Makes table.md from matrix.csv (run in this folder: python3 table.py > table.md): per scene and
# kind of ray the fastest of LST, stackless and cwbvh against rt-pipeline, and the fastest of all
# our methods, counted as docs/gpu-benchmark.md's matrix counts them (primary = the cast frame's
# rate; the others = the rays a mode adds over the time it adds to the same method's cast frame).
import csv
t = {}
for r in csv.DictReader(open('matrix.csv')):
    t[(r['scene'], r['mode'], r['method'])] = (float(r['median_ms']), *(int(r[k]) for k in ['primary', 'shadow', 'secondary', 'ao', 'diffuse']))
def rate(sc, kind, m):
    cast = t[(sc, 'cast', m)]
    if kind == 'primary':
        return cast[1] / cast[0] / 1000
    mode = {'shadow + secondary': 'whitted1', 'AO': 'ao8', 'diffuse': 'diffuse'}[kind]
    x = t[(sc, mode, m)]
    n = {'whitted1': x[2] + x[3], 'ao8': x[4], 'diffuse': x[5]}[mode]
    return n / (x[0] - cast[0]) / 1000
ours = ['lst', 'stackless', 'sst', 'sst-subgroup', 'cwbvh']
print("| scene | ray type | fastest of ours (Mrays/s) | rt-pipeline | ours / rt-pipeline | cwbvh / LST | SST / LST |")
print("|---|---|---|--:|--:|--:|--:|")
for sc in ['bunny', 'car', 'dragon', 'forest', 'million', 'room']:
    for k in ['primary', 'shadow + secondary', 'AO', 'diffuse']:
        best = max((rate(sc, k, m), m) for m in ours)
        rt = rate(sc, k, 'rt-pipeline')
        lst = rate(sc, k, 'lst')
        print(f"| {sc} | {k} | {best[1]} {best[0]:.0f} | {rt:.0f} | {best[0] / rt:.2f} | {rate(sc, k, 'cwbvh') / lst:.2f} | {rate(sc, k, 'sst') / lst:.2f} |")
