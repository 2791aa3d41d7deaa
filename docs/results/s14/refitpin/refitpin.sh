#!/bin/bash
# usage: refitpin.sh ROUNDS -> refit-only runs, pinned and --no-pin alternated, into $OUT
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
A="--meshes meshes --scenes sphere,bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:default,hostas:refit,embree:refit --threads 16 --reps 9 --no-trace --pairs 0"
for i in $(seq 1 $1); do
  ./hostas-peers-s14 $A --json $OUT/pin$i.jsonl > /dev/null 2>&1
  ./hostas-peers-s14 $A --no-pin --json $OUT/free$i.jsonl > /dev/null 2>&1
done
