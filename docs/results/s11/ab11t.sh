#!/bin/bash
# s10 final (383d3e4) vs s11, alternating, one thread: fast-trace build and trace against Embree
# MEDIUM (does reusing structure memory change trace?). usage: ab11t.sh FIRST LAST (into /tmp/abt)
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/abt
for r in $(seq ${1:-1} ${2:-3}); do for b in old new; do
  if [ $b = old ]; then B=./hostas-peers-s10; else B=./hostas-peers-s11; fi
  $B --meshes meshes --scenes bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --reps 3 --no-refit --json /tmp/abt/tr_${b}_$r.jsonl > /dev/null 2>&1
  echo "$r $b $(date +%s)"
done; done
