#!/usr/bin/env python3
"""Per stack placement: the paired trace medians (hostas ÷ Embree MEDIUM) of a stack sweep
(`padsweep.sh`/`stack_sweep.sh` write DIR/BIN_PAD_REP.jsonl), one line per binary and scene,
each placement's value (median over repetitions) in order of PAD, then their median, least
and greatest.
usage: pads.py DIR [MEASURE]   (MEASURE: "primary rays 1T", the default, or "incoherent rays 1T")
"""
import collections
import glob
import json
import re
import statistics
import sys

d = sys.argv[1]
measure = sys.argv[2] if len(sys.argv) > 2 else "primary rays 1T"
res = collections.defaultdict(lambda: collections.defaultdict(list))
for f in glob.glob(d + "/*_*_*.jsonl"):
    m = re.match(r".*/([a-z0-9]+)_(\d+)_(\d+)\.jsonl$", f)
    if not m:
        continue
    b, pad, _rep = m.groups()
    for line in open(f):
        r = json.loads(line)
        if r.get("measure") == measure and r.get("embree_key") == "MEDIUM" and "median" in r:
            res[(b, r["scene"])][int(pad)].append(r["median"])
for (b, s), v in sorted(res.items()):
    vals = [statistics.median(v[p]) for p in sorted(v)]
    print(f"{b:6} {s:10} " + " ".join(f"{x:.2f}" for x in vals)
          + f"   med {statistics.median(vals):.3f} min {min(vals):.2f} max {max(vals):.2f}")
