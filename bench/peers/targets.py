#!/usr/bin/env python3
"""The issue-5 target table from one or more `hostas-peers --json` runs.

Each ratio is taken within one run (hostas and the peer measured in the same process), then
the median over runs is printed with the range, so a noisy machine shows as a wide range
instead of a lucky cell. Usage: targets.py RUN1.jsonl [RUN2.jsonl ...] > table.md
"""
import json
import statistics
import sys


def rows(path):
    out = {}
    for line in open(path):
        d = json.loads(line)
        if "library" in d:
            out[(d["scene"], d["library"], d["key"])] = d
    return out


def get(r, scene, lib, key, field, threads=None):
    d = r.get((scene, lib, key))
    if d is None:
        return None
    v = d.get(field)
    if threads is not None:
        v = (v or {}).get(str(threads))
    return v


# (column title, target, numerator, denominator); each side is (lib, key, field, threads).
COLUMNS = [
    ("fast-trace build ÷ Embree MEDIUM, 1T", "≥ 1.5",
     ("hostas", "fast_trace", "build_mtris_s", 1), ("embree", "MEDIUM", "build_mtris_s", 1)),
    ("fast-trace SAH(1,1) ÷ Embree MEDIUM, 8-wide", "≤ 1.0",
     ("hostas", "fast_trace", "sah8_ct1_ci1", None), ("embree", "MEDIUM", "sah8_ct1_ci1", None)),
    ("fast-build build ÷ Embree LOW, 1T", "≥ 1.5",
     ("hostas", "fast_build", "build_mtris_s", 1), ("embree", "LOW", "build_mtris_s", 1)),
    ("fast-trace primary ÷ MEDIUM", "≥ 1.0",
     ("hostas", "fast_trace", "primary_mrays_s_1t", None), ("embree", "MEDIUM", "primary_mrays_s_1t", None)),
    ("fast-trace incoherent ÷ MEDIUM", "≥ 1.0",
     ("hostas", "fast_trace", "incoherent_mrays_s_1t", None), ("embree", "MEDIUM", "incoherent_mrays_s_1t", None)),
]
# Absolute figures: (title, target, (lib, key, field, threads)).
ABSOLUTE = [
    ("B/tri hostas fast-trace (compacted)", "≤ 40", ("hostas", "fast_trace", "bytes_per_tri", None)),
    ("B/tri Embree MEDIUM", "", ("embree", "MEDIUM", "bytes_per_tri", None)),
    ("refit 1T Mtris/s hostas", "≥ 80", ("hostas", "default", "refit_mtris_s", 1)),
    ("refit 1T Embree", "", ("embree", "refit", "refit_mtris_s", 1)),
    ("refit all-threads hostas", "", ("hostas", "default", "refit_mtris_s", "all")),
    ("refit all-threads Embree", "", ("embree", "refit", "refit_mtris_s", "all")),
]


def fmt(values, digits=2):
    values = [v for v in values if v is not None]
    if not values:
        return "–"
    m = statistics.median(values)
    if len(values) == 1:
        return f"{m:.{digits}f}"
    return f"{m:.{digits}f} ({min(values):.{digits}f}–{max(values):.{digits}f})"


def main(paths):
    runs = [rows(p) for p in paths]
    # The all-threads count of each run (the JSON keys threads by number).
    for r in runs:
        for d in r.values():
            n = d.get("threads_all")
            if n:
                for f in ("refit_mtris_s", "build_mtris_s"):
                    if str(n) in (d.get(f) or {}):
                        d[f]["all"] = d[f][str(n)]
    scenes = []
    for r in runs:
        for (s, _, _) in r:
            if s not in scenes:
                scenes.append(s)
    titles = [f"{c[0]} ({c[1]})" for c in COLUMNS] + [
        f"{a[0]} ({a[1]})" if a[1] else a[0] for a in ABSOLUTE
    ]
    print(f"Runs: {len(runs)} ({', '.join(paths)}). Cells: median over runs (min–max).\n")
    print("| scene | " + " | ".join(titles) + " |")
    print("|---|" + "--:|" * len(titles))
    for s in scenes:
        cells = []
        for _, _, num, den in COLUMNS:
            ratios = []
            for r in runs:
                a, b = get(r, s, *num), get(r, s, *den)
                if a and b:
                    ratios.append(a / b)
            cells.append(fmt(ratios))
        for _, _, src in ABSOLUTE:
            cells.append(fmt([get(r, s, *src) for r in runs], 1))
        print(f"| {s} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
