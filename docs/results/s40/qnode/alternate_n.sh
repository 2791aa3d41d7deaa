#!/usr/bin/env bash
# Several builds of the benchmark in turn, round by round, for SECS seconds (default 270), so
# that all see the same machine drift: round N runs ./hostas-peers-NAME for each NAME in
# NAMES and writes /tmp/altn/NAME_N.jsonl; the folder is packed into $OUT/altn.tar (the lent
# machine's output folder). ARGS: the benchmark's arguments. Summarize with
# `rounds.py altn NAME...`. Run from a folder holding the binaries, libembree3.so.3(.xz) and
# libtbb.so.12, e.g.
#   SECS=240 NAMES="old new" ARGS="--scenes bunny,sponza --libs hostas,embree \
#     --variants hostas:fast_trace,embree:MEDIUM --threads 1 --reps 1 --no-refit --pairs 5 \
#     --meshes m" bash alternate_n.sh
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/altn
end=$(( $(date +%s) + ${SECS:-270} ))
r=1
while [ "$(date +%s)" -lt $end ]; do
  for b in $NAMES; do
    # shellcheck disable=SC2086 # ARGS is a list of arguments
    ./hostas-peers-$b $ARGS --json /tmp/altn/${b}_$r.jsonl > /dev/null 2> /tmp/altn/${b}_$r.err
  done
  echo "round $r done $(date +%T)"
  r=$((r+1))
done
tar -C /tmp -cf "${OUT:-.}/altn.tar" altn
