#!/usr/bin/env python3
# Makes table.md from all.txt (run in this folder: python3 table.py > table.md): the fastest of
# LST, stackless and cwbvh per scene and kind of ray against rt-pipeline, counted as
# docs/gpu-benchmark.md's matrix counts them (primary = the cast frame's rate; the others = the
# rays a mode adds over the time it adds to the same method's cast frame).
rows = [l.strip().split(',') for l in open('all.txt')]
t = {}
for r in rows:
    t[(r[0], r[1], r[2])] = (float(r[3]), *map(int, r[4:9]))
def rate(sc, kind, m):
    cast = t[(sc, 'cast', m)]
    if kind == 'primary':
        return cast[1] / cast[0] / 1000
    mode = {'shadow + secondary': 'whitted1', 'AO': 'ao8', 'diffuse': 'diffuse'}[kind]
    x = t[(sc, mode, m)]
    n = {'whitted1': x[2] + x[3], 'ao8': x[4], 'diffuse': x[5]}[mode]
    return n / (x[0] - cast[0]) / 1000
print("| scene | ray type | fastest of ours (Mrays/s) | rt-pipeline | ours / rt-pipeline |")
print("|---|---|---|--:|--:|")
for sc in ['bunny', 'car', 'dragon', 'forest', 'million', 'room']:
    for k in ['primary', 'shadow + secondary', 'AO', 'diffuse']:
        best = max((rate(sc, k, m), m) for m in ['lst', 'stackless', 'cwbvh'])
        rt = rate(sc, k, 'rt-pipeline')
        print(f"| {sc} | {k} | {best[1]} {best[0]:.0f} | {rt:.0f} | {best[0] / rt:.2f} |")
