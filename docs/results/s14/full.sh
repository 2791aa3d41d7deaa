#!/bin/bash
# usage: full.sh N... -> full peers runs rN.{jsonl,md,err} into $OUT (s14 binary)
cd "$(dirname "$0")"; (test -f libembree3.so.3 || xz -dk libembree3.so.3.xz); export LD_LIBRARY_PATH=$PWD
for n in "$@"; do
  ./hostas-peers-s14 --meshes meshes --threads 16 --json $OUT/r$n.jsonl > $OUT/r$n.md 2>$OUT/r$n.err
done
nproc; lscpu | grep "Model name"
