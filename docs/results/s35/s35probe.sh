#!/usr/bin/env bash
# Refit of the 1M scenes: isolated vs inside longer runs, and the machine's page settings.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
export LD_LIBRARY_PATH=$PWD
B=./hostas-peers-s34a
{
nproc; lscpu | grep "Model name"; lscpu | grep -i numa
for f in enabled defrag khugepaged/defrag; do echo "thp $f: $(cat /sys/kernel/mm/transparent_hugepage/$f)"; done
grep -i -E "huge|anon" /proc/meminfo
} > $OUT/machine.txt 2>&1
r() { tag=$1; shift; /usr/bin/time -v $B --scenes sphere,boxes --variants hostas:default,hostas:refit,embree:refit "$@" --json $OUT/$tag.jsonl > $OUT/$tag.md 2> $OUT/$tag.err; grep -E "Maximum resident|Minor|Major" $OUT/$tag.err >> $OUT/machine.txt; echo "$tag done $(date +%T)" >> $OUT/machine.txt; }
for round in 1 2; do
  r iso$round --threads 1 --no-trace
  r iso16_$round --threads 16 --no-trace
  r tr16_$round --threads 16
done
grep -i -E "AnonHuge" /proc/meminfo >> $OUT/machine.txt
cd $OUT && tar -cf all.tar *.jsonl *.md *.err && rm -f *.jsonl *.md *.err
