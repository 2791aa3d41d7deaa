#!/usr/bin/env python3
"""Summarize runs of several hostas-peers binaries on one machine: the paired trace medians
(hostas ÷ Embree, alternated back to back within each run) per binary, every run's value and
their median. DIR holds NAME_*.jsonl per binary NAME (what alternate_n.sh and stack_sweep.sh
write: NAME_ROUND.jsonl, NAME_PAD_REP.jsonl), in the order of their numbers.
usage: rounds.py DIR NAME... > table.md
"""
import glob
import json
import os
import re
import statistics
import sys


def main(folder, names):
    cells = {}
    for name in names:
        paths = glob.glob(os.path.join(folder, f"{name}_*.jsonl"))
        key = lambda p: [int(x) for x in re.findall(r"\d+", os.path.basename(p)[len(name):])]
        for path in sorted(paths, key=key):
            for line in open(path):
                d = json.loads(line)
                if "paired" in d and d.get("median") is not None and "build" not in d["measure"]:
                    cells.setdefault((d["scene"], d["measure"]), {}).setdefault(name, []).append(d["median"])
    print(f"Paired medians (hostas ÷ Embree) per run; median over runs. Folder: {folder}\n")
    print("| scene | measure | " + " | ".join(names) + " |")
    print("|---|---|" + "--:|" * len(names))
    for (scene, measure), per in sorted(cells.items()):
        row = []
        for name in names:
            v = per.get(name, [])
            row.append(f"**{statistics.median(v):.3f}** ({', '.join(f'{x:.2f}' for x in v)})" if v else "")
        print(f"| {scene} | {measure} | " + " | ".join(row) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2:])
