#!/usr/bin/env bash
# Primary rays fed in 2x4 / 4x2 pixel tiles (HOSTAS_TILE=4 / 2) against scanline order (0),
# alternated; paired ratios against Embree MEDIUM.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
mkdir -p m; for f in mxz/*.xz; do xz -dc $f > m/$(basename $f .xz); done
mkdir -p /tmp/tile
for round in 1 2 3; do
  for t in 0 4 2; do
    HOSTAS_TILE=$t ./hostas-peers-s35t --meshes m --scenes soup,boxes,sphere,bunny,sponza --kinds primary \
      --libs hostas,embree --variants hostas:fast_trace,embree:MEDIUM --threads 1 --no-refit \
      --pairs 9 --reps 1 --big-reps 1 --json /tmp/tile/t${t}_r$round.jsonl > /tmp/tile/t${t}_r$round.md 2> /tmp/tile/t${t}_r$round.err
    echo "round $round tile $t done $(date +%T)"
  done
done
tar -C /tmp -cf $OUT/tile.tar tile
