#!/usr/bin/env bash
# Which part of a full run slows the paired one-thread trace: configurations of the
# benchmark, each a fresh process, round by round; JSON into $OUT/probe/CFG_ROUND.jsonl.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do test -f m/$(basename ${f%.xz}) || xz -dc $f > m/$(basename ${f%.xz}); done
mkdir -p $OUT/probe
S=${SCENES:-sibenik,conference}
lean="--kinds primary,incoherent --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --no-refit --pairs 9 --reps 1 --big-reps 1"
for r in $(seq 1 ${ROUNDS:-3}); do
  for c in ${CFGS:-lean1 lean16 full16 full1 he16}; do
    case $c in
      lean1) a="$lean --threads 1" ;;
      lean16) a="$lean --threads 16" ;;
      full16) a="--threads 16" ;;
      full1) a="--threads 1" ;;
      he16) a="--libs hostas,embree --threads 16" ;;
      *) a="$EXTRA_ARGS" ;;
    esac
    ./hostas-peers-new --meshes m --scenes $S $a --json $OUT/probe/${c}_$r.jsonl > /dev/null 2> $OUT/probe/${c}_$r.err
    echo "$c $r done $(date +%T)"
  done
done
