#!/usr/bin/env bash
# Steps run on a lent machine from a folder holding prebuilt binaries (a benchmark built with
# `-C target-cpu=native` and stripped), libembree3.so.3.xz, libtbb.so.12, alternate.sh and the
# meshes; results go to $OUT (the device tool's output folder).
#
# usage: lent.sh STEP...
#   fullN   full run of ./hostas-peers-new over the seven scenes (rN.jsonl/.md/.err)
#   crownN  the crown with the targets' variants (crownN.*), from the folder crown/
#   altA-B  the four meshes' fast-trace trace, ./hostas-peers-old and ./hostas-peers-new
#           alternated, rounds A..B, into $OUT/alt.tar (one file: the machine returns at most
#           eight)
# MESHES (default meshes) is the folder of the seven scenes' meshes.
set -u
cd "$(dirname "$0")"
meshes=${MESHES:-meshes}
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
nproc; lscpu | grep "Model name"
for s in "$@"; do
  case $s in
    full*) ./hostas-peers-new --meshes "$meshes" --threads 16 --scenes sphere,soup,boxes,bunny,sponza,sibenik,conference \
             --json $OUT/r${s#full}.jsonl > $OUT/r${s#full}.md 2> $OUT/r${s#full}.err ;;
    crown*) ./hostas-peers-new --meshes crown --threads 16 --scenes crown \
             --variants hostas:fast_trace,hostas:fast_build,hostas:default,hostas:refit,embree:LOW,embree:MEDIUM,embree:MEDIUM_ROBUST,embree:refit \
             --json $OUT/crown${s#crown}.jsonl > $OUT/crown${s#crown}.md 2> $OUT/crown${s#crown}.err ;;
    alt*) r=${s#alt}; mkdir -p /tmp/alt; bash ./alternate.sh ./hostas-peers-old ./hostas-peers-new ${r%-*} ${r#*-} /tmp/alt -- \
             --scenes bunny,sponza,sibenik,conference --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM,embree:MEDIUM_ROBUST \
             --threads 1 --reps 3 --no-refit --meshes "$meshes"
          tar -C /tmp -cf $OUT/alt.tar alt ;;
  esac
  echo "step $s done at $(date +%T)"
done
