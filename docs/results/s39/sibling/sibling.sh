#!/usr/bin/env bash
# Which CPU shares CPU 0's core? The paired one-thread primary trace of Sibenik (hostas
# fast-trace against Embree MEDIUM) pinned to CPU 0 while one busy shell loop runs on CPU k,
# for k = 1..15 in turn, each after a run with no loop (idle): ROUNDS times.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do test -f m/$(basename ${f%.xz}) || xz -dc $f > m/$(basename ${f%.xz}); done
P=/tmp/sib; mkdir -p $P
cat /sys/devices/system/cpu/cpu0/topology/thread_siblings_list > $P/topology.txt 2>&1
lscpu -e >> $P/topology.txt 2>&1
run() { taskset -c 0 ./hostas-peers-new --meshes m --scenes sibenik --libs hostas,embree --kinds primary \
  --variants hostas:fast_trace,embree:MEDIUM --no-refit --pairs 5 --reps 1 --threads 1 \
  --json $P/$1.jsonl > /dev/null 2>> $P/err.txt; }
for r in $(seq 1 ${ROUNDS:-2}); do
  for k in $(seq 1 15); do
    run idle_${r}_$k
    taskset -c $k bash -c 'while :; do :; done' & pid=$!
    sleep 0.5; run spin_${r}_$k; kill $pid; wait $pid 2>/dev/null
  done
  pids=""; for c in $(seq 1 15); do taskset -c $c bash -c 'while :; do :; done' & pids="$pids $!"; done
  sleep 0.5; run all_$r; kill $pids; wait $pids 2>/dev/null
  echo "round $r $(date +%T)"
done
tar -C /tmp -cf $OUT/sib.tar sib
