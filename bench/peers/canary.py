#!/usr/bin/env python3
"""The paired trace ratios by how busy the core's L2 cache was when each pair ran.

Before each pair, `hostas-peers` times a walk through 1.5 MiB of memory that fits the lent
Xeon's L2 (`canary_us` in the JSON; `paired.rs`, `canary`). A slow canary means something
else took the L2 (or the L3) just then. This pools the pairs of every file given, cuts them
into thirds by their canary time (the same cuts for every cell) and prints, per trace
target and scene, the median pair ratio (hostas ÷ Embree throughput) in each third, and the
rank correlation of the canary with each side's time. Context for the target table, not a
replacement: `targets.py` reads every pair alike. With `--l1`, the pairs are cut by the walk
through 24 KiB instead (`canary_l1_us`: the L1 data cache, which a core's two hardware
threads share; runs from the forty-first session on).
usage: canary.py [--l1] RUN.jsonl... > by-canary.md
"""
import json
import statistics
import sys


def pairs(paths, field):
    """(scene, measure, embree key) -> [(canary µs, hostas ms, Embree ms)] of the trace targets."""
    out = {}
    for path in paths:
        for line in open(path):
            d = json.loads(line)
            if field not in d or "build" in d.get("measure", ""):
                continue
            key = (d["scene"], d["measure"], d["embree_key"])
            out.setdefault(key, []).extend(zip(d[field], d["hostas_ms"], d["embree_ms"]))
    return out


def ranks(v):
    order = sorted(range(len(v)), key=lambda i: v[i])
    r = [0] * len(v)
    for k, i in enumerate(order):
        r[i] = k
    return r


def spearman(a, b):
    """Spearman's rank correlation: Pearson's of the ranks (the pairs' times have no ties)."""
    return statistics.correlation(ranks(a), ranks(b)) if len(a) > 1 else float("nan")


def main(args):
    field = "canary_l1_us" if args[:1] == ["--l1"] else "canary_us"
    paths = args[1:] if field == "canary_l1_us" else args
    if not paths:
        sys.exit(__doc__)
    cells = pairs(paths, field)
    every = sorted(c for v in cells.values() for c, _, _ in v)
    if not every:
        sys.exit(f"no pair has a {field} time (runs before the "
                 + ("forty-first" if field == "canary_l1_us" else "thirty-ninth")
                 + " session's benchmark)")
    cut = [every[len(every) // 3], every[2 * len(every) // 3]]
    print(f"{len(every)} pairs from {len(paths)} files; canary thirds: below {cut[0]:.0f} µs, "
          f"{cut[0]:.0f}-{cut[1]:.0f} µs, above {cut[1]:.0f} µs (lowest {every[0]:.0f} µs)\n")
    print("| scene | measure | Embree | quiet third | middle third | busy third | all | "
          "corr(canary, hostas ms) | corr(canary, Embree ms) |")
    print("|---|---|---|--:|--:|--:|--:|--:|--:|")
    for (scene, measure, key), v in sorted(cells.items()):
        thirds = [[], [], []]
        for c, h, e in v:
            thirds[(c >= cut[0]) + (c >= cut[1])].append(e / h)
        med = lambda r: f"{statistics.median(r):.3f} ({len(r)})" if r else "-"
        cs, hs, es = zip(*v)
        print(f"| {scene} | {measure} | {key} | " + " | ".join(med(t) for t in thirds)
              + f" | {med([e / h for _, h, e in v])} | {spearman(cs, hs):.2f} | {spearman(cs, es):.2f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
