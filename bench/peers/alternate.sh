#!/usr/bin/env bash
# Alternates two builds of the benchmark, round by round, so that both see the same machine
# drift: round N runs OLD, then NEW, each writing DIR/tr_old_N.jsonl and DIR/tr_new_N.jsonl.
# Summarize with `alternation.py DIR` (per scene, new ÷ old as the median of the rounds'
# ratios). Rounds FIRST..LAST, so that a long alternation can be split over several calls.
#
# usage: alternate.sh OLD NEW FIRST LAST [DIR] [-- benchmark arguments]
#   OLD, NEW  hostas-peers binaries (e.g. two `run.sh` builds copied aside)
#   DIR       output folder (default: alternation)
# Default benchmark arguments: one thread, the fast-trace build and trace against Embree
# MEDIUM on the real meshes; anything after `--` replaces them (e.g. `-- --variants
# hostas:default,embree:refit --no-trace` for refits). LD_LIBRARY_PATH and the mesh folder
# are the caller's (`--meshes` among the arguments where ../shared/meshes is absent).
set -euo pipefail
if [ $# -lt 4 ]; then
    sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//' >&2
    exit 2
fi
old=$1 new=$2 first=$3 last=$4
shift 4
dir=alternation
if [ $# -gt 0 ] && [ "$1" != "--" ]; then
    dir=$1
    shift
fi
args=(--scenes bunny,sponza,sibenik,conference --libs hostas,embree
    --variants hostas:fast_trace,embree:MEDIUM --threads 1 --reps 3 --no-refit)
if [ $# -gt 0 ] && [ "$1" = "--" ]; then
    shift
    args=("$@")
fi
for b in "$old" "$new"; do
    [ -x "$b" ] || { echo "alternate.sh: $b is not an executable" >&2; exit 1; }
done
mkdir -p "$dir"
for r in $(seq "$first" "$last"); do
    for side in old new; do
        if [ $side = old ]; then bin=$old; else bin=$new; fi
        "$bin" "${args[@]}" --json "$dir/tr_${side}_$r.jsonl" > /dev/null
        echo "alternate.sh: round $r $side done ($(date +%T))" >&2
    done
done
