import json,glob,re,collections,sys,statistics
d=sys.argv[1]
res=collections.defaultdict(lambda: collections.defaultdict(list))
for f in glob.glob(d+'/*_*_*.jsonl'):
    m=re.match(r'.*/([a-z0-9]+)_(\d+)_(\d+)\.jsonl$',f)
    if not m: continue
    b,pad,rep=m.groups()
    for l in open(f):
        r=json.loads(l)
        if r.get('measure')=='incoherent rays 1T' and r.get('embree_key')=='MEDIUM' and 'median' in r:
            res[(b,r['scene'])][int(pad)].append(r['median'])
for (b,s),v in sorted(res.items()):
    pads=sorted(v)
    vals=[statistics.median(v[p]) for p in pads]
    print(f"{b:6} {s:8} " + " ".join(f"{x:.2f}" for x in vals) + f"   med {statistics.median(vals):.3f} min {min(vals):.2f} max {max(vals):.2f}")
