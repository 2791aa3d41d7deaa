import sys,collections,subprocess,glob,os,statistics as st
# usage: agg.py DIR NEW
d_,new=sys.argv[1],sys.argv[2]
d=collections.defaultdict(list)
for f in sorted(glob.glob(d_+"/*.jsonl")):
    b=os.path.basename(f).replace("crown_","").split("_")[0]
    if b not in ("s34a",new): continue
    out=subprocess.run(["python3","/work/main/bench/peers/pairs.py",f],capture_output=True,text=True).stdout
    for l in out.splitlines():
        p=l.split()
        if len(p)<3: continue
        d[(p[1].rstrip(":"),b)].append(float(p[-1]))
for s in ["soup","boxes","sphere","bunny","sponza","sibenik","conference","crown"]:
    a=d[(s,"s34a")]; b=d[(s,new)]
    if not a or not b: continue
    print(f"{s:11} main {min(a):.3f}-{max(a):.3f} med {st.median(a):.3f} (n={len(a)}) | {new} {min(b):.3f}-{max(b):.3f} med {st.median(b):.3f}  x{st.median(b)/st.median(a):.3f}  ", " ".join(f"{x:.2f}" for x in b))
