#!/usr/bin/env bash
# Does the trace speed depend on where the stack starts? ASLR off (setarch -R), the stack
# moved by an environment variable of PAD bytes; each setting run REPS times.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
mkdir -p /tmp/pad
setarch -R true && echo "setarch -R works" || echo "setarch -R fails"
for rep in $(seq 1 ${REPS:-2}); do for BIN in ${BINS:-new}; do
for pad in ${PADS:-0 256 512 768 1024 1280 1536 1792 2048 2304 2560 2816 3072 3328 3584 3840}; do
  p=$(head -c $pad /dev/zero | tr '\0' x)
  setarch -R env -i LD_LIBRARY_PATH=$PWD P=$p ./hostas-peers-$BIN $ARGS --json /tmp/pad/${BIN}_${pad}_$rep.jsonl > /dev/null 2>/tmp/pad/${BIN}_${pad}_$rep.err || echo "run $pad failed"
done
done; echo "rep $rep done $(date +%T)"
done
tar -C /tmp -cf $OUT/pad.tar pad
