#!/bin/bash
# usage: run15.sh STEP...   (on the lent machine; results into $OUT)
#   fullN   full run of the new binary over the seven scenes (rN.jsonl/.md/.err)
#   crownN  the crown with the targets' variants (crownN.*)
#   altA-B  soup fast-trace trace, old (93b574b) and new binaries alternated, rounds A..B
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
nproc; lscpu | grep "Model name"
for s in "$@"; do
  case $s in
    full*) ./hostas-peers-new --meshes meshes --threads 16 --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference \
             --json $OUT/r${s#full}.jsonl > $OUT/r${s#full}.md 2> $OUT/r${s#full}.err ;;
    crown*) ./hostas-peers-new --meshes meshes --threads 16 --scenes crown \
             --variants hostas:fast_trace,hostas:fast_build,hostas:default,hostas:refit,embree:LOW,embree:MEDIUM,embree:refit \
             --json $OUT/crown${s#crown}.jsonl > $OUT/crown${s#crown}.md 2> $OUT/crown${s#crown}.err ;;
    alt*) r=${s#alt}; bash ./alternate.sh ./hostas-peers-old ./hostas-peers-new ${r%-*} ${r#*-} $OUT/alt -- \
             --scenes soup --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --reps 3 --no-refit --meshes meshes ;;
  esac
  echo "step $s done at $(date +%T)"
done
# clampA-B: soup fast-trace trace, the read-past 8-wide leaves (8932351, hostas-peers-new) against
# lanes clamped to the leaf (hostas-peers-clamp), rounds A..B, into $OUT/clamp
for s in "$@"; do
  case $s in
    clamp*) r=${s#clamp}; bash ./alternate.sh ./hostas-peers-new ./hostas-peers-clamp ${r%-*} ${r#*-} $D/clamp -- \
             --scenes soup,boxes --libs hostas,embree --variants hostas:fast_trace,hostas:fast_build,embree:MEDIUM,embree:LOW --threads 1 --reps 3 --no-refit --meshes meshes ;;
  esac
done
