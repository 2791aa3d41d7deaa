#!/usr/bin/env bash
# Is the lent machine's slow stretch load on the other CPUs? The paired one-thread trace
# (bunny, Sibenik; hostas fast-trace against Embree MEDIUM) pinned to CPU 0, in rounds of
# three conditions: idle; spin (15 busy shell loops, one on each of CPUs 1-15); mem (a
# 15-thread fast build of the 1M soup, repeated, on CPUs 1-15: memory and L3 traffic).
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do test -f m/$(basename ${f%.xz}) || xz -dc $f > m/$(basename ${f%.xz}); done
P=/tmp/busy; mkdir -p $P
nproc; lscpu | grep -E "Model name|Thread|MHz"
run() { taskset -c 0 ./hostas-peers-new --meshes m --scenes bunny,sibenik --libs hostas,embree \
  --variants hostas:fast_trace,embree:MEDIUM --no-refit --pairs 7 --reps 1 --threads 1 \
  --json $P/$1.jsonl > /dev/null 2>> $P/err.txt; }
for r in $(seq 1 ${ROUNDS:-4}); do
  run idle_$r
  pids=""; for c in $(seq 1 15); do taskset -c $c bash -c 'while :; do :; done' & pids="$pids $!"; done
  sleep 1; run spin_$r; kill $pids; wait $pids 2>/dev/null
  ( while :; do taskset -c 1-15 ./hostas-peers-new --scenes soup --libs hostas --variants hostas:fast_build \
      --threads 15 --reps 50 --no-trace --no-refit > /dev/null 2>&1; done ) & hog=$!
  sleep 3; run mem_$r; kill $hog; pkill -f "scenes soup"; wait 2>/dev/null
  echo "round $r $(date +%T)"
done
grep -h "MHz" /proc/cpuinfo | sort | uniq -c | head -5 > $P/mhz.txt
tar -C /tmp -cf $OUT/busy.tar busy
