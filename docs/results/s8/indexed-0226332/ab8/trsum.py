#!/usr/bin/env python3
"""Summarize ab8.sh: per scene, medians (min-max) over runs of hostas fast-trace (and default)
build Mtris/s, B/tri, primary and incoherent Mrays/s, and their ratios to Embree MEDIUM within
each run. usage: trsum.py DIR OLD_LABEL NEW_LABEL"""
import json, sys, glob, statistics, collections
d, lo, ln = sys.argv[1:4]
cells = collections.defaultdict(lambda: collections.defaultdict(list))
for b in ('old', 'new'):
    for path in sorted(glob.glob(f'{d}/tr_{b}_*.jsonl')):
        rs = [json.loads(l) for l in open(path)]
        by = {(r['scene'], r['library'], r['key']): r for r in rs if 'library' in r}
        for (sc, lib, key), r in by.items():
            if lib != 'hostas': continue
            e = by.get((sc, 'embree', 'MEDIUM'), {})
            tag = {'fast_trace': 'FT', 'default': 'default'}[key]
            for m, name in [('build', 'build Mtris/s'), ('primary_mrays_s_1t', 'primary Mrays/s'), ('incoherent_mrays_s_1t', 'incoherent Mrays/s')]:
                v = r['build_mtris_s'].get('1') if m == 'build' else r.get(m)
                pv = (e.get('build_mtris_s') or {}).get('1') if m == 'build' else e.get(m)
                if v is None: continue
                cells[(sc, f'{tag} {name}')][b].append(v)
                if pv: cells[(sc, f'{tag} {name.split()[0]} ÷ Embree MEDIUM')][b].append(v / pv)
            cells[(sc, f'{tag} B/tri')][b].append(r['bytes_per_tri'])
fmt = lambda v: f'{statistics.median(v):.2f} ({min(v):.2f}–{max(v):.2f})' if v else '–'
order = ['sphere', 'soup', 'boxes', 'bunny', 'sponza', 'sibenik', 'conference']
print(f'| scene | measure | {lo} | {ln} |\n|---|---|--:|--:|')
for (sc, m) in sorted(cells, key=lambda k: (order.index(k[0]) if k[0] in order else 99, k[1])):
    c = cells[(sc, m)]
    print(f'| {sc} | {m} | {fmt(c["old"])} | {fmt(c["new"])} |')
