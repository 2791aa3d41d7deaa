#!/usr/bin/env bash
# Refit protocols alternated on one lease: 5 after 1 (the old small-scene protocol), 11 after 1
# (the new one), 3 after 0 (the old big-scene one); rounds of each, hostas default + Embree refit.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m && for f in mxz/*.xz; do test -f m/$(basename $f .xz) || xz -dc $f > m/$(basename $f .xz); done
for r in 1 2 3 4 5 6; do
  for p in "5 1" "11 1" "3 0"; do
    set -- $p
    ./hostas-peers-new --meshes m --threads 16 --scenes bunny,sibenik,conference --libs hostas,embree \
      --variants hostas:default,hostas:refit,embree:refit --no-trace --pairs 0 \
      --refit-reps $1 --refit-warmup $2 --json $OUT/p$1-$2-r$r.jsonl > /dev/null 2>&1
  done
done
cd $OUT && tar -cf proto.tar p*.jsonl && rm p*.jsonl
