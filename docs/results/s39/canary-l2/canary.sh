#!/usr/bin/env bash
# Does the canary (timed before each pair) say which state the machine is in? The paired one-thread trace
# (bunny, Sibenik, the conference; hostas fast-trace against Embree MEDIUM) pinned to CPU 0, in rounds of
# two conditions: idle; spin (15 busy shell loops, one on each of CPUs 1-15).
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do test -f m/$(basename ${f%.xz}) || xz -dc $f > m/$(basename ${f%.xz}); done
P=/tmp/canary; mkdir -p $P
nproc; lscpu | grep -E "Model name|Thread|MHz"
run() { taskset -c 0 ./hostas-peers-new --meshes m --scenes bunny,sibenik,conference --libs hostas,embree \
  --variants hostas:fast_trace,embree:MEDIUM --no-refit --pairs 7 --reps 1 --threads 1 \
  --json $P/$1.jsonl > /dev/null 2>> $P/err.txt; }
for r in $(seq 1 ${ROUNDS:-4}); do
  run idle_$r
  pids=""; for c in $(seq 1 15); do taskset -c $c bash -c 'while :; do :; done' & pids="$pids $!"; done
  sleep 1; run spin_$r; kill $pids; wait $pids 2>/dev/null
  echo "round $r $(date +%T)"
done
grep -h "MHz" /proc/cpuinfo | sort | uniq -c | head -5 > $P/mhz.txt
tar -C /tmp -cf $OUT/canary.tar canary
