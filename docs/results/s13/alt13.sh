#!/bin/bash
# usage: alt13.sh FIRST LAST -> s12 vs s13 alternation (bench/peers/alternate.sh), tarred to $OUT/abt.tgz
R=$PWD; cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
$R/bench/peers/alternate.sh ./hostas-peers-s12 ./hostas-peers-s13 $1 $2 /tmp/abt -- --meshes meshes --scenes bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --reps 3 --no-refit 2>&1 | grep alternate.sh
cd /tmp && tar czf $OUT/abt.tgz abt
