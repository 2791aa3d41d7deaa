#!/usr/bin/env python3
"""The issue-5 target table from one or more `hostas-peers --json` runs.

Each ratio is taken within one run (hostas and the peer measured in the same process), then
the median over runs is printed with the range, so a noisy machine shows as a wide range
instead of a lucky cell. The timed ratios come from each run's paired phase where it has one
(the median of that run's pair ratios, hostas and Embree alternated back to back); runs
without paired records (older runs, `--pairs 0`, a skipped pair) fall back to the ratio of the
two per-library medians, and such cells are marked. Usage:
targets.py RUN1.jsonl [RUN2.jsonl ...] > table.md

Below the table, each target's cells: the median (unrounded) against the target, and how many
runs were at it on their own, so that a cell which flips from run to run shows as such.
"""
import json
import statistics
import sys


def rows(path):
    """The run's per-library rows by (scene, library, key), and its paired medians by
    (scene, paired target)."""
    out, paired = {}, {}
    for line in open(path):
        d = json.loads(line)
        if "library" in d:
            out[(d["scene"], d["library"], d["key"])] = d
        elif "paired" in d and d.get("median") is not None:
            paired[(d["scene"], d["paired"])] = d["median"]
    return out, paired


def get(r, scene, lib, key, field, threads=None):
    d = r.get((scene, lib, key))
    if d is None:
        return None
    v = d.get(field)
    if threads is not None:
        v = (v or {}).get(str(threads))
    return v


# (column title, target, numerator, denominator, paired target or None); each side is
# (lib, key, field, threads).
COLUMNS = [
    ("fast-trace build ÷ Embree MEDIUM, 1T", "≥ 1.5",
     ("hostas", "fast_trace", "build_mtris_s", 1), ("embree", "MEDIUM", "build_mtris_s", 1),
     "fast_trace_build_1t_vs_medium"),
    ("fast-trace SAH(1,1) ÷ Embree MEDIUM, 8-wide", "≤ 1.0",
     ("hostas", "fast_trace", "sah8_ct1_ci1", None), ("embree", "MEDIUM", "sah8_ct1_ci1", None),
     None),
    ("fast-build build ÷ Embree LOW, 1T", "≥ 1.5",
     ("hostas", "fast_build", "build_mtris_s", 1), ("embree", "LOW", "build_mtris_s", 1),
     "fast_build_build_1t_vs_low"),
    ("fast-trace primary ÷ MEDIUM", "≥ 1.0",
     ("hostas", "fast_trace", "primary_mrays_s_1t", None), ("embree", "MEDIUM", "primary_mrays_s_1t", None),
     "fast_trace_primary_vs_medium"),
    ("fast-trace incoherent ÷ MEDIUM", "≥ 1.0",
     ("hostas", "fast_trace", "incoherent_mrays_s_1t", None), ("embree", "MEDIUM", "incoherent_mrays_s_1t", None),
     "fast_trace_incoherent_vs_medium"),
    # Context, no target: against Embree's robust mode, the nearest to hostas's exact tests.
    ("fast-trace primary ÷ MEDIUM robust", "",
     ("hostas", "fast_trace", "primary_mrays_s_1t", None), ("embree", "MEDIUM_ROBUST", "primary_mrays_s_1t", None),
     "fast_trace_primary_vs_medium_robust"),
    ("fast-trace incoherent ÷ MEDIUM robust", "",
     ("hostas", "fast_trace", "incoherent_mrays_s_1t", None), ("embree", "MEDIUM_ROBUST", "incoherent_mrays_s_1t", None),
     "fast_trace_incoherent_vs_medium_robust"),
]
# Marks a timed-ratio cell where at least one run had no paired median.
FALLBACK = "†"
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


def meets(value, target):
    """Whether `value` is at `target` ("≥ 1.5", "≤ 40"); None for a column without one."""
    if not target or value is None:
        return None
    op, bound = target.split()
    return value >= float(bound) if op == "≥" else value <= float(bound)


def main(paths):
    runs = [rows(p) for p in paths]
    # The all-threads count of each run (the JSON keys threads by number).
    for r, _ in runs:
        for d in r.values():
            n = d.get("threads_all")
            if n:
                for f in ("refit_mtris_s", "build_mtris_s"):
                    if str(n) in (d.get(f) or {}):
                        d[f]["all"] = d[f][str(n)]
    scenes = []
    for r, _ in runs:
        for (s, _, _) in r:
            if s not in scenes:
                scenes.append(s)
    titles = [f"{c[0]} ({c[1]})" if c[1] else c[0] for c in COLUMNS] + [
        f"{a[0]} ({a[1]})" if a[1] else a[0] for a in ABSOLUTE
    ]
    with_pairs = sum(1 for _, p in runs if p)
    print(f"Runs: {len(runs)} ({', '.join(paths)}). Cells: median over runs (min–max).")
    print(f"Build and trace ratios: each run's paired median (hostas and Embree alternated back to "
          f"back, median of the pair ratios; {with_pairs} of {len(runs)} runs have paired records); "
          f"{FALLBACK}: at least one run had none for that cell and gave the ratio of its two "
          f"per-library medians instead. SAH: ratio of the two values.\n")
    print("| scene | " + " | ".join(titles) + " |")
    print("|---|" + "--:|" * len(titles))
    # Per targeted column: (scene, median, runs at target, runs) for the summary.
    verdicts = {c[0]: [] for c in COLUMNS + ABSOLUTE if c[1]}
    for s in scenes:
        cells = []
        for title, target, num, den, pname in COLUMNS:
            ratios, fell_back = [], False
            for r, p in runs:
                if pname and (s, pname) in p:
                    ratios.append(p[(s, pname)])
                    continue
                a, b = get(r, s, *num), get(r, s, *den)
                if a and b:
                    ratios.append(a / b)
                    fell_back = fell_back or pname is not None
            cells.append(fmt(ratios) + (f" {FALLBACK}" if fell_back else ""))
            verdict(verdicts, title, target, s, ratios)
        for title, target, src in ABSOLUTE:
            values = [v for v in (get(r, s, *src) for r, _ in runs) if v is not None]
            cells.append(fmt(values, 1))
            verdict(verdicts, title, target, s, values)
        print(f"| {s} | " + " | ".join(cells) + " |")
    summary(verdicts, {c[0]: c[1] for c in COLUMNS + ABSOLUTE})


def verdict(verdicts, title, target, scene, values):
    """Notes a targeted cell's median and its runs at target."""
    if target and values:
        at = sum(1 for v in values if meets(v, target))
        verdicts[title].append((scene, statistics.median(values), at, len(values)))


def summary(verdicts, targets):
    """The cells whose median meets its target, and per cell how many runs did."""
    cells = [(t, c) for t, cs in verdicts.items() for c in cs]
    met = [(t, c) for t, c in cells if meets(c[1], targets[t])]
    print(f"\nMedians at target: {len(met)} of {len(cells)} cells. Per target, each scene's "
          f"median (unrounded) and the runs at target on their own:\n")
    for t, cs in verdicts.items():
        parts = [f"{s} {m:.3f} {'met' if meets(m, targets[t]) else 'not met'} ({at}/{n})"
                 for s, m, at, n in cs]
        print(f"- {t} ({targets[t]}): " + "; ".join(parts))


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1:])
