#!/bin/bash
# usage: alt14.sh FIRST LAST -> s14 (d37dc63) vs s14b (buffer memory not zeroed again) build alternation, tarred to $OUT/abt.tgz
R=$PWD; cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
$R/bench/peers/alternate.sh ./hostas-peers-s14 ./hostas-peers-s14b $1 $2 /tmp/abt -- --meshes meshes --scenes bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_build,embree:LOW,hostas:fast_trace,embree:MEDIUM --threads 1 --reps 7 --no-refit --no-trace --pairs 7 2>&1 | grep alternate.sh
cd /tmp && tar czf $OUT/abt.tgz abt
