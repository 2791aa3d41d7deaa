#!/usr/bin/env python3
"""Instructions executed per machine instruction, from a callgrind profile taken with
`--dump-instr=yes`, printed beside the disassembly (objdump) of the functions whose demangled
name contains a given text: where inside an inlined loop the instructions go, which the
per-source-line view of callgrind_annotate cannot show.

usage: callgrind_asm.py PROFILE BINARY NAME [MIN]
  prints the total, then every instruction of the matching functions executed at least MIN
  times (default 1; 0 also prints the ones never executed), as `count address: instruction`.

Self cost only: the cost of a call is counted in the callee, not at the call instruction.
"""
import collections
import re
import subprocess
import sys


def costs(path, binary):
    """Executed count per instruction address of `binary`, and each address's function."""
    names = {}

    def name(kind, text):
        m = re.match(r"\((\d+)\)(?: (.*))?", text)
        key = (kind, m.group(1))
        if m.group(2):
            names[key] = m.group(2)
        return names.get(key, "?")

    obj = fn = None
    addr = 0
    after_call = False
    cost = collections.Counter()
    function = {}
    target = binary.rsplit("/", 1)[-1]
    for line in open(path):
        line = line.rstrip("\n")
        if line.startswith("ob="):
            obj = name("ob", line[3:])
        elif line.startswith("fn="):
            fn = name("fn", line[3:])
        elif line.startswith(("cob=", "cfn=", "cfi=", "cfl=")):
            kind = {"cob": "ob", "cfn": "fn", "cfi": "fl", "cfl": "fl"}[line[:3]]
            name(kind, line[4:])
        elif line.startswith(("fl=", "fi=", "fe=")):
            name("fl", line[3:])
        elif line.startswith("calls="):
            # The next cost line is the call's inclusive cost, not this function's own.
            after_call = True
        elif line and line[0] in "+-*0":
            parts = line.split()
            a = parts[0]
            if a[0] in "+-":
                addr += int(a[1:], 0) * (1 if a[0] == "+" else -1)
            elif a != "*":
                addr = int(a, 16)
            if after_call:
                after_call = False
            elif len(parts) >= 3 and obj and obj.endswith(target):
                cost[addr] += int(parts[2])
                function[addr] = fn
    return cost, function


def main():
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    path, binary, text = sys.argv[1:4]
    least = int(sys.argv[4]) if len(sys.argv) > 4 else 1
    cost, function = costs(path, binary)
    chosen = {a: c for a, c in cost.items() if text in function[a]}
    if not chosen:
        sys.exit(f"no executed instruction of a function matching {text!r}")
    print("total", sum(chosen.values()), "instructions", len(chosen))
    lo, hi = min(chosen), max(chosen)
    listing = subprocess.run(
        ["objdump", "-d", "--no-show-raw-insn", "-C",
         f"--start-address={lo:#x}", f"--stop-address={hi + 16:#x}", binary],
        capture_output=True, text=True, check=True,
    ).stdout
    for line in listing.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s*(.*)", line)
        if not m:
            continue
        a = int(m.group(1), 16)
        c = chosen.get(a, 0)
        if c >= least and (c > 0 or least == 0):
            print(f"{c:9d} {a:x}: {m.group(2)}")


if __name__ == "__main__":
    main()
