#!/usr/bin/env bash
# The crown's primary rays: main (s34a) against $B, alternated; paired ratios against Embree MEDIUM.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/s36
for round in $(seq ${1:-1} ${2:-2}); do
  for b in s34a $B; do
    ./hostas-peers-$b --meshes crown --scenes crown --kinds primary \
      --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --no-refit \
      --pairs 9 --reps 1 --big-reps 1 --json /tmp/s36/crown_${b}_r$round.jsonl > /tmp/s36/crown_${b}_r$round.md 2> /tmp/s36/crown_${b}_r$round.err
    echo "crown round $round $b done $(date +%T)"
  done
done
tar -C /tmp -cf $OUT/s36.tar s36
