#!/usr/bin/env bash
# A full run of one scene with its threads' CPU time sampled every half second (which threads
# work while the paired one-thread trace is timed), then lean configurations again.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do test -f m/$(basename ${f%.xz}) || xz -dc $f > m/$(basename ${f%.xz}); done
P=/tmp/probe; mkdir -p $P
./hostas-peers-new --meshes m --scenes sibenik --threads 16 --json $P/sampled.jsonl > /dev/null 2> $P/sampled.err &
pid=$!; t0=$(date +%s.%N)
while kill -0 $pid 2>/dev/null; do
  now=$(date +%s.%N)
  for t in /proc/$pid/task/*; do
    echo "$(echo "$now - $t0" | bc) $(cut -d' ' -f1,2,14,15,39 $t/stat 2>/dev/null)"
  done
  sleep 0.5
done > $P/threads.txt
lean="--kinds primary,incoherent --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --no-refit --pairs 9 --reps 1 --big-reps 1"
for r in 1 2; do
  ./hostas-peers-new --meshes m --scenes sibenik $lean --threads 1 --json $P/lean1_$r.jsonl > /dev/null 2>&1
  ./hostas-peers-new --meshes m --scenes sibenik $lean --threads 16 --json $P/lean16_$r.jsonl > /dev/null 2>&1
  ./hostas-peers-new --meshes m --scenes sibenik --libs hostas,embree --threads 16 --json $P/he16_$r.jsonl > /dev/null 2>&1
  ./hostas-peers-new --meshes m --scenes sibenik --libs hostas,embree --threads 1 --json $P/he1_$r.jsonl > /dev/null 2>&1
  echo "round $r $(date +%T)"
done
tar -C /tmp -cf $OUT/probe.tar probe
