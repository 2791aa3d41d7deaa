#!/usr/bin/env bash
# Primary rays, paired against Embree MEDIUM: packets (auto) at several thresholds vs one ray
# at a time (never), rounds alternated. Results: $OUT/pk.tar
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do xz -dc $f > m/$(basename $f .xz); done
lscpu | grep -E 'Model name'
mkdir -p /tmp/pk
for r in $(seq 1 ${ROUNDS:-2}); do
  for v in ${VARIANTS:-never:pk auto:pk}; do
    mode=${v%%:*}; b=${v#*:}
    HOSTAS_INTERLEAVE=$mode ./hostas-peers-$b --meshes m --scenes ${SCENES:-sphere,soup,boxes,bunny,sponza,sibenik,conference} \
      --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --kinds ${KINDS:-primary} --no-refit --embree-sah-proxy off \
      --reps 1 --warmup 0 --big-reps 1 --pairs 7 --big-pairs 1 --threads 1 --json /tmp/pk/${mode}_${b}_$r.jsonl > /tmp/pk/${mode}_${b}_$r.md 2>&1
    echo "$r $v $(date +%T)"
  done
done
tar -C /tmp -cf $OUT/pk.tar pk
