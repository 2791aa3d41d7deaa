#!/bin/bash
# old (a9abff6) vs new, alternating: builds 1T on the meshes, trace on every scene
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/ab
for r in 1 2 3; do for b in old new; do
  B=./hostas-peers; [ $b = old ] && B=./hostas-peers-old
  $B --meshes meshes --scenes bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,hostas:fast_build,embree:MEDIUM,embree:LOW --no-trace --no-refit --threads 1 --reps 9 --json /tmp/ab/build_${b}_$r.jsonl > /dev/null 2>&1
  $B --meshes meshes --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --reps 1 --warmup 0 --no-refit --threads 1 --json /tmp/ab/trace_${b}_$r.jsonl > /dev/null 2>&1
done; done
tar czf $OUT/ab.tgz -C /tmp/ab .
