#!/usr/bin/env bash
# Primary (or other) rays paired against Embree MEDIUM under several binaries and
# HOSTAS_INTERLEAVE modes, in rounds that alternate them (on the lent machine, from a folder of
# prebuilt binaries hostas-peers-BIN beside libembree3.so.3(.xz) and libtbb.so.12).
# env: VARIANTS="mode:BIN ..." (mode: auto, never, packets, always), ROUNDS (2), SCENES
# (the seven), KINDS (primary), MESHES (meshes). Writes /tmp/modes/MODE_BIN_ROUND.jsonl, packed
# into $OUT/modes.tar; summary: python3 bench/peers/rounds.py DIR MODE_BIN ...
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p /tmp/modes
for r in $(seq 1 ${ROUNDS:-2}); do
  for v in ${VARIANTS:-never:new auto:new}; do
    mode=${v%%:*}; b=${v#*:}
    HOSTAS_INTERLEAVE=$mode ./hostas-peers-$b --meshes ${MESHES:-meshes} \
      --scenes ${SCENES:-sphere,soup,boxes,bunny,sponza,sibenik,conference} \
      --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --kinds ${KINDS:-primary} \
      --no-refit --embree-sah-proxy off --reps 1 --warmup 0 --big-reps 1 --pairs 7 --big-pairs 1 \
      --threads 1 --json /tmp/modes/${mode}_${b}_$r.jsonl > /tmp/modes/${mode}_${b}_$r.md 2>&1
    echo "$r $v $(date +%T)"
  done
done
tar -C /tmp -cf $OUT/modes.tar modes
