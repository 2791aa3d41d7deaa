#!/usr/bin/env python3
"""Each paired trace target's times pair by pair (hostas ms | Embree ms, in the order run) and
its median ratio, per file, with the CPU the run's one-thread phases were pinned to and the
L2 canary timed before each pair (µs, see `canary.py`): what shows whether a low ratio came
from a few pairs or from all (a slow stretch of seconds on the lent machine slows every pair
in it, hostas more than Embree).
usage: pairs.py RUN.jsonl... [--measure "primary rays 1T"]
"""
import json
import re
import sys


def main(args):
    measure = "primary rays 1T"
    if "--measure" in args:
        i = args.index("--measure")
        measure = args[i + 1]
        del args[i : i + 2]
    if not args:
        sys.exit(__doc__)
    for path in args:
        cpu = "?"
        for line in open(path):
            d = json.loads(line)
            # A scene's summary notes where its one-thread phases ran.
            for note in d.get("notes") or []:
                m = re.search(r"pinned to CPU (\d+)", note)
                if m:
                    cpu = m.group(1)
            if d.get("measure") == measure and "hostas_ms" in d:
                h = " ".join(f"{x:.1f}" for x in d["hostas_ms"])
                e = " ".join(f"{x:.1f}" for x in d["embree_ms"])
                # The L2 canary before each pair (µs; runs since the thirty-ninth session).
                c = " ".join(f"{x:.0f}" for x in d.get("canary_us", []))
                c = f"  canary {c}" if c else ""
                print(f"{path} {d['scene']} (CPU {cpu}): {h} | {e}  ratio {d['median']:.3f}{c}")


if __name__ == "__main__":
    main(sys.argv[1:])
