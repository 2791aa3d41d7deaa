#!/usr/bin/env python3
"""Summarize an old/new alternation (ab7.sh): per scene, medians (min-max) over runs of
hostas Mtris/s and ratios to Embree within each run. usage: absum.py DIR OLD_LABEL NEW_LABEL"""
import json, sys, glob, statistics, collections
d, lo, ln = sys.argv[1:4]
def rows(path):
    out = []
    for l in open(path):
        r = json.loads(l)
        if 'library' in r: out.append(r)
    return out
# cells[(scene, measure)][b] = [values per run]
cells = collections.defaultdict(lambda: collections.defaultdict(list))
for b in ('old', 'new'):
    for path in sorted(glob.glob(f'{d}/build_{b}_*.jsonl')):
        rs = rows(path); by = {(r['scene'], r['library'], r['key']): r for r in rs}
        for (sc, lib, key), r in by.items():
            if lib != 'hostas' or not r.get('build_mtris_s'): continue
            v = r['build_mtris_s'].get('1')
            peer = by.get((sc, 'embree', 'MEDIUM' if key == 'fast_trace' else 'LOW'))
            tag = 'FT' if key == 'fast_trace' else 'FB'
            cells[(sc, f'{tag} Mtris/s')][b].append(v)
            if peer and peer.get('build_mtris_s', {}).get('1'):
                cells[(sc, f'{tag} ÷ Embree {"MEDIUM" if tag=="FT" else "LOW"}')][b].append(v / peer['build_mtris_s']['1'])
    for path in sorted(glob.glob(f'{d}/refit_{b}_*.jsonl')):
        rs = rows(path)
        for r in rs:
            if r['library'] == 'hostas' and r.get('refit_mtris_s', {}).get('1'):
                cells[(r['scene'], 'refit 1T Mtris/s')][b].append(r['refit_mtris_s']['1'])
            if r['library'] == 'embree' and r.get('refit_mtris_s', {}).get('1'):
                cells[(r['scene'], 'Embree refit 1T Mtris/s')][b].append(r['refit_mtris_s']['1'])
fmt = lambda v: f'{statistics.median(v):.2f} ({min(v):.2f}–{max(v):.2f})' if v else '–'
order = ['sphere', 'soup', 'boxes', 'bunny', 'sponza', 'sibenik', 'conference']
print(f'| scene | measure | {lo} | {ln} |\n|---|---|--:|--:|')
for (sc, m) in sorted(cells, key=lambda k: (order.index(k[0]) if k[0] in order else 99, k[1])):
    c = cells[(sc, m)]
    print(f'| {sc} | {m} | {fmt(c["old"])} | {fmt(c["new"])} |')
