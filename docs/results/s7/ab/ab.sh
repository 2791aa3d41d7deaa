#!/bin/bash
# old (previous session's binary) vs new, alternating, one thread: builds (fast-trace, fast-build,
# Embree MEDIUM and LOW) and refits (hostas and Embree) on every scene but the crown
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/ab
for r in 1 2 3; do for b in old new; do
  B=./hostas-peers; [ $b = old ] && B=./hostas-peers-old
  $B --meshes meshes --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,hostas:fast_build,embree:MEDIUM,embree:LOW --no-trace --no-refit --threads 1 --reps 5 --json /tmp/ab/build_${b}_$r.jsonl > /dev/null 2>&1
  $B --meshes meshes --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:default,hostas:refit,embree:refit --no-trace --threads 1 --reps 5 --json /tmp/ab/refit_${b}_$r.jsonl > /dev/null 2>&1
  echo "$r $b $(date +%s)"
done; done
tar czf $OUT/ab.tgz -C /tmp/ab .
