#!/usr/bin/env bash
# The same binary (hostas-peers-BIN, as for modes.sh) pinned to several CPUs in turn
# (`taskset -c`), the meshes' primary rays paired against Embree MEDIUM, ROUNDS times; each
# process's /proc/stat line for its CPU before and after (steal and irq time) in stat.txt.
# env: BIN (new), CPUS ("0 5 10 15"), ROUNDS (2), SCENES (the four meshes), MESHES (meshes).
# Writes /tmp/nz/cCPU_ROUND.jsonl, packed into $OUT/nz.tar.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/nz
for r in $(seq 1 ${ROUNDS:-2}); do
  for c in ${CPUS:-0 5 10 15}; do
    a=$(grep "^cpu$c " /proc/stat)
    taskset -c $c ./hostas-peers-${BIN:-new} --meshes ${MESHES:-meshes} \
      --scenes ${SCENES:-bunny,sponza,sibenik,conference} --libs hostas,embree \
      --variants hostas:fast_trace,embree:MEDIUM --kinds primary --no-refit --embree-sah-proxy off \
      --reps 1 --warmup 0 --big-reps 1 --pairs 7 --big-pairs 1 --threads 1 \
      --json /tmp/nz/c${c}_$r.jsonl > /tmp/nz/c${c}_$r.md 2>&1
    echo "$r cpu$c before: $a after: $(grep "^cpu$c " /proc/stat)" | tee -a /tmp/nz/stat.txt
  done
done
tar -C /tmp -cf $OUT/nz.tar nz
