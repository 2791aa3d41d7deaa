#!/usr/bin/env python3
"""Summarize an alternation of two hostas-peers binaries (old, new) run in turns on one machine.

DIR holds PREFIX_old_N.jsonl and PREFIX_new_N.jsonl for rounds N (what alternate.sh writes,
with PREFIX tr). Per scene and measure (hostas fast-trace build
Mtris/s, fast-build build Mtris/s, primary / incoherent Mrays/s, one thread; the default
preset's one-thread refit when present), the median over rounds of each binary, its ratio to
Embree within the same run in parentheses (MEDIUM; LOW for the fast build; Embree's refit for
the refit), and new ÷ old as the median of each round's ratio; then each round's paired
medians (the run's paired phase: hostas and Embree alternated back to back), which carry none
of the machine's drift between the two binaries' turns.
usage: alternation.py DIR [PREFIX] > table.md
"""
import glob
import json
import os
import re
import statistics
import sys

MEASURES = [
    ("build Mtris/s", "fast_trace", lambda d: (d.get("build_mtris_s") or {}).get("1"), "MEDIUM"),
    ("fast-build build Mtris/s", "fast_build", lambda d: (d.get("build_mtris_s") or {}).get("1"), "LOW"),
    ("primary Mrays/s", "fast_trace", lambda d: d.get("primary_mrays_s_1t"), "MEDIUM"),
    ("incoherent Mrays/s", "fast_trace", lambda d: d.get("incoherent_mrays_s_1t"), "MEDIUM"),
    ("refit 1T Mtris/s", "default", lambda d: (d.get("refit_mtris_s") or {}).get("1"), "refit"),
]


def rows(path):
    out = {}
    for line in open(path):
        d = json.loads(line)
        if "library" in d:
            out[(d["scene"], d["library"], d["key"])] = d
        elif "paired" in d:
            out[(d["scene"], "paired", d["paired"])] = d
    return out


def main(folder, prefix):
    runs = {}
    for path in glob.glob(os.path.join(folder, f"{prefix}_*_*.jsonl")):
        m = re.fullmatch(rf"{re.escape(prefix)}_(old|new)_(\d+)\.jsonl", os.path.basename(path))
        if m:
            runs[(m.group(1), int(m.group(2)))] = rows(path)
    rounds = sorted({n for (b, n) in runs if (("old", n) in runs and ("new", n) in runs)})
    scenes = []
    for r in runs.values():
        for (s, _, _) in r:
            if s not in scenes:
                scenes.append(s)
    print(f"{len(rounds)} rounds of old then new. Medians over rounds; in parentheses the ratio to "
          "Embree in the same run; new ÷ old is the median of each round's ratio.\n")
    print("| scene | measure | old (÷ Embree) | new (÷ Embree) | new ÷ old |")
    print("|---|---|--:|--:|--:|")
    for s in scenes:
        for title, key, get, peer in MEASURES:
            vals = {"old": [], "new": []}
            rel = {"old": [], "new": []}
            for n in rounds:
                for b in vals:
                    r = runs[(b, n)]
                    h = get(r.get((s, "hostas", key), {}))
                    e = get(r.get((s, "embree", peer), {}))
                    vals[b].append(h)
                    if h and e:
                        rel[b].append(h / e)
            pairs = [(o, n) for o, n in zip(vals["old"], vals["new"]) if o and n]
            if not pairs:
                continue
            med = lambda v: statistics.median([x for x in v if x]) if any(v) else float("nan")
            cell = lambda b: f"{med(vals[b]):.2f} ({med(rel[b]):.2f})"
            ratio = statistics.median(n / o for o, n in pairs)
            print(f"| {s} | {title} | {cell('old')} | {cell('new')} | {ratio:.3f} |")
    paired_table(runs, rounds, scenes)


def paired_table(runs, rounds, scenes):
    """Each round's paired median (hostas and Embree alternated back to back within the run)
    per binary: the ratios that carry none of the drift between the two binaries' turns."""
    medians = {}
    for (b, n), r in runs.items():
        for (s, lib, key), d in r.items():
            if lib == "paired" and d.get("median") is not None:
                # The robust pairs time the same measure against another Embree variant.
                measure = d["measure"]
                if d.get("embree_key", "").endswith("_ROBUST"):
                    measure += f" vs {d['embree_key']}"
                medians.setdefault((s, measure), {}).setdefault(b, {})[n] = d["median"]
    if not medians:
        return
    print("\nPaired medians (hostas ÷ Embree) per round, old then new; median over rounds.\n")
    print("| scene | measure | old per round | old | new per round | new |")
    print("|---|---|---|--:|---|--:|")
    for s in scenes:
        for (scene, measure), v in sorted(medians.items()):
            if scene != s:
                continue
            per = {b: [v.get(b, {}).get(n) for n in rounds] for b in ("old", "new")}
            if not all(x is not None for b in per for x in per[b]):
                continue
            row = lambda b: (", ".join(f"{x:.3f}" for x in per[b]), statistics.median(per[b]))
            (o, om), (n, nm) = row("old"), row("new")
            print(f"| {s} | {measure} | {o} | {om:.3f} | {n} | {nm:.3f} |")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else "tr")
