#!/usr/bin/env bash
# Primary rays: $A against $B, alternated round by round;
# paired ratios against Embree MEDIUM.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do xz -dc $f > m/$(basename $f .xz); done
mkdir -p /tmp/s37
for round in $(seq ${1:-1} ${2:-3}); do
  for b in ${A:-s37base} ${B:-s37a}; do
    ./hostas-peers-$b --meshes m --scenes soup,boxes,sphere,bunny,sponza,sibenik,conference --kinds primary \
      --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --no-refit \
      --pairs 9 --reps 1 --big-reps 1 --json /tmp/s37/${b}_r$round.jsonl > /tmp/s37/${b}_r$round.md 2> /tmp/s37/${b}_r$round.err
    echo "round $round $b done $(date +%T)"
  done
done
tar -C /tmp -cf $OUT/s37.tar s37
