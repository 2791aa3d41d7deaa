#!/bin/bash
# c466a5d (session 7) vs new, alternating, one thread: fast-trace and default builds, bytes and
# trace (primary, incoherent), with Embree MEDIUM, on every scene but the crown
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/ab
for r in 1 2 3; do for b in old new; do
  B=./hostas-peers; [ $b = old ] && B=./hostas-peers-c466
  $B --meshes meshes --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,hostas:default,embree:MEDIUM --no-refit --threads 1 --reps 3 --json /tmp/ab/tr_${b}_$r.jsonl > /dev/null 2>&1
  echo "$r $b $(date +%s)"
done; done
tar czf $OUT/ab8.tgz -C /tmp/ab .
