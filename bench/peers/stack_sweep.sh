#!/usr/bin/env bash
# Does a build's trace speed depend on where the process's stack begins? Runs
# ./hostas-peers-NAME (each NAME in BINS) with address-space randomization off (setarch -R)
# and the stack moved by an environment variable of PAD bytes, for each PAD in PADS (default
# 0 to 3840 by 256), REPS times (default 1), writing /tmp/pad/NAME_PAD_REP.jsonl; the folder
# is packed into $OUT/pad.tar. ARGS: the benchmark's arguments (as for alternate_n.sh).
# Summarize with `rounds.py pad NAME...`.
cd "$(dirname "$0")"
test -f libembree3.so.3 || xz -dk libembree3.so.3.xz
mkdir -p /tmp/pad
setarch -R true || { echo "stack_sweep.sh: setarch -R is not allowed here" >&2; exit 1; }
for rep in $(seq 1 "${REPS:-1}"); do
  for b in ${BINS:-new}; do
    for pad in ${PADS:-0 256 512 768 1024 1280 1536 1792 2048 2304 2560 2816 3072 3328 3584 3840}; do
      p=$(head -c "$pad" /dev/zero | tr '\0' x)
      # shellcheck disable=SC2086 # ARGS is a list of arguments
      setarch -R env -i LD_LIBRARY_PATH="$PWD" P="$p" ./hostas-peers-$b $ARGS \
        --json /tmp/pad/${b}_${pad}_$rep.jsonl > /dev/null 2> /tmp/pad/${b}_${pad}_$rep.err \
        || echo "stack_sweep.sh: $b with $pad bytes failed" >&2
    done
  done
  echo "rep $rep done $(date +%T)"
done
tar -C /tmp -cf "${OUT:-.}/pad.tar" pad
