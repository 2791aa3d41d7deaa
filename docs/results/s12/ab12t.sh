#!/bin/bash
# s11 final (fb0df27) vs s12, alternating, one thread: trace against Embree MEDIUM (the
# per-ray changes of the twelfth session). usage: ab12t.sh FIRST LAST (into $OUT/abt)
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/abt
for r in $(seq ${1:-1} ${2:-3}); do for b in old new; do
  if [ $b = old ]; then B=./hostas-peers-s11; else B=./hostas-peers-s12; fi
  $B --meshes meshes --scenes bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --reps 3 --no-refit --json /tmp/abt/tr_${b}_$r.jsonl > /dev/null 2>&1
  echo "$r $b $(date +%s)"
done; done
cd /tmp && tar czf $OUT/abt.tgz abt
