#!/bin/bash
# s9 final (813ac98) vs new, alternating, one thread: fast-trace build and trace with Embree
# MEDIUM on every scene but the crown. usage: ab10.sh FIRST LAST
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/ab
for r in $(seq ${1:-1} ${2:-3}); do for b in old new; do
  if [ $b = old ]; then B=./hostas-peers-s9; X=""; else B=./hostas-peers; X="--pairs 0"; fi
  $B --meshes meshes --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --reps 3 --no-refit $X --json /tmp/ab/tr_${b}_$r.jsonl > /dev/null 2>&1
  echo "$r $b $(date +%s)"
done; done
tar czf $OUT/ab10.tgz -C /tmp/ab .
