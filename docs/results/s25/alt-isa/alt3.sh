#!/usr/bin/env bash
# Three builds in turn, round by round (z3, z4, emr), for as long as the time allows.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
lscpu | grep -E 'Model name|Model:'
mkdir -p /tmp/alt3
end=$(( $(date +%s) + ${SECS:-270} ))
r=1
while [ $(date +%s) -lt $end ]; do
  for b in z3 z4 emr; do
    ./hostas-peers-$b --scenes bunny,sponza,sibenik,conference --libs hostas,embree \
      --variants hostas:fast_trace,embree:MEDIUM,embree:MEDIUM_ROBUST --threads 1 --reps 3 --no-refit \
      --meshes m --json /tmp/alt3/${b}_$r.jsonl > /dev/null 2>&1
  done
  echo "round $r done $(date +%T)"
  r=$((r+1))
done
tar -C /tmp -cf $OUT/alt3.tar alt3
