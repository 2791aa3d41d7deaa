import json,glob,collections,statistics,sys
d=collections.defaultdict(list)
for f in sorted(glob.glob(sys.argv[1]+'/*.jsonl')):
    mode=f.split('/')[-1].split('_')[1]
    for l in open(f):
        j=json.loads(l)
        if j.get('refit_mtris_s'): d[(j['scene'],mode)].append(round(j['refit_mtris_s']['1'],1))
modes=sys.argv[2].split(',')
for s in ['sphere','soup','boxes','bunny','sponza','sibenik','conference','crown']:
    print(s.ljust(11), '  '.join(f"{m}: {statistics.median(d[(s,m)]) if d[(s,m)] else '-':>6} {d[(s,m)]}" for m in modes))
