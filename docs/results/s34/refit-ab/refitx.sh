#!/usr/bin/env bash
# refitx.sh ROUNDS MODES... : refit-only runs of ./hostas-peers-x per HOSTAS_REFIT mode, alternated
set -u
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do test -f m/$(basename $f .xz) || xz -dc $f > m/$(basename $f .xz); done
cp crown/* m/ 2>/dev/null
nproc; lscpu | grep "Model name"
rounds=$1; shift
for r in $(seq 1 $rounds); do
  for m in "$@"; do
    HOSTAS_REFIT=$m ./hostas-peers-x --meshes m --threads 1 --scenes ${SCENES:-sphere,soup,boxes,bunny,sponza,sibenik,conference} \
      --libs hostas --variants hostas:default,hostas:refit --no-trace --refit-reps 21 --refit-warmup 3 \
      --json $OUT/rf${TAG:-}_${m}_$r.jsonl > /dev/null 2> $OUT/rf${TAG:-}_${m}_$r.err
    echo "round $r mode $m done at $(date +%T)"
  done
done
