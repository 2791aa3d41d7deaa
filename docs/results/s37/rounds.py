"""Summarises alternated rounds: rounds.py DIR BASE NEW.

For each scene, the paired ratios (hostas / Embree MEDIUM, from bench/peers/pairs.py) of the
runs named BASE_* and NEW_* in DIR: range, median, and NEW's median over BASE's.
"""
import collections
import glob
import os
import statistics as st
import subprocess
import sys

PAIRS = os.path.join(os.path.dirname(__file__), "..", "..", "..", "bench", "peers", "pairs.py")
SCENES = ["soup", "boxes", "sphere", "bunny", "sponza", "sibenik", "conference", "crown"]


def main(folder, base, new):
    ratios = collections.defaultdict(list)
    for f in sorted(glob.glob(os.path.join(folder, "*.jsonl"))):
        b = os.path.basename(f).split("_")[0]
        if b not in (base, new):
            continue
        out = subprocess.run(["python3", PAIRS, f], capture_output=True, text=True).stdout
        for line in out.splitlines():
            p = line.split()
            if len(p) >= 3:
                ratios[(p[1].rstrip(":"), b)].append(float(p[-1]))
    for s in SCENES:
        a, b = ratios[(s, base)], ratios[(s, new)]
        if not a or not b:
            continue
        print(f"{s:11} {base} {min(a):.2f}-{max(a):.2f} median {st.median(a):.3f} (n={len(a)}) | "
              f"{new} {min(b):.2f}-{max(b):.2f} median {st.median(b):.3f} (n={len(b)}) "
              f"x{st.median(b) / st.median(a):.3f}")


if __name__ == "__main__":
    main(*sys.argv[1:4])
