#!/bin/bash
# usage: numa.sh -> topology, then fast-build pairs on bunny/sibenik unpinned vs pinned (taskset), interleaved
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
lscpu | grep -E "Model name|Socket|NUMA|Core|Thread|MHz"; (numactl -H 2>/dev/null || cat /sys/devices/system/node/node*/cpulist)
A="--meshes meshes --scenes bunny,sibenik,sponza --libs hostas,embree --variants hostas:fast_build,embree:LOW,hostas:fast_trace,embree:MEDIUM --threads 1 --reps 5 --no-refit --no-trace --pairs 7"
for i in 1 2 3; do
  ./hostas-peers-s13 $A --json $OUT/free$i.jsonl > /dev/null 2>&1
  taskset -c 3 ./hostas-peers-s13 $A --json $OUT/pin$i.jsonl > /dev/null 2>&1
done
