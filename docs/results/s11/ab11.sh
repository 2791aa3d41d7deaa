#!/bin/bash
# s10 final (383d3e4) vs s11, alternating, one thread, builds only (fast-build vs Embree LOW,
# fast-trace vs MEDIUM, with the paired phase) on every scene but the crown. usage: ab11.sh FIRST LAST
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
for r in $(seq ${1:-1} ${2:-3}); do for b in old new; do
  if [ $b = old ]; then B=./hostas-peers-s10; else B=./hostas-peers-s11; fi
  $B --meshes meshes --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_build,hostas:fast_trace,embree:LOW,embree:MEDIUM --threads 1 --no-trace --no-refit --json $OUT/bd_${b}_$r.jsonl > /dev/null 2>$OUT/bd_${b}_$r.err
  echo "$r $b $(date +%s)"
done; done
