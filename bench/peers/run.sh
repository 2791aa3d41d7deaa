#!/usr/bin/env bash
# Builds the peer benchmark in release with `-C target-cpu=native` (Rust: hostas, obvhs and
# this crate; C++: the tinybvh shim and tinybvh-rs, both -march=native; Embree is the system
# library, which picks its ISA at run time) and runs it. Arguments go to the benchmark
# (see `run.sh --help`). Environment:
#   PEERS_FEATURES   cargo features (default: "hostas,cli-mesh": the hostas adapter, and meshes
#                    loaded with hostas_cli::mesh; "" builds without either, using the
#                    stand-in mesh loader, for when the core does not compile)
#   PEERS_JOBS       cargo -j (default 2)
set -euo pipefail
cd "$(dirname "$0")"
if ! dpkg -s libembree-dev >/dev/null 2>&1; then
    echo "run.sh: libembree-dev is missing; run bench/peers/install.sh (as root) first" >&2
    exit 1
fi
export RUSTFLAGS="${RUSTFLAGS:-} -C target-cpu=native"
# The hostas revision measured, for the report header (a "+" marks uncommitted core changes).
rev=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
if [ -n "$(git status --porcelain -- ../../crates/hostas 2>/dev/null)" ]; then rev="$rev+"; fi
export PEERS_GIT_REV="git $rev"
features="${PEERS_FEATURES-hostas,cli-mesh}"
t0=$(date +%s)
cargo build --release -j "${PEERS_JOBS:-2}" --no-default-features --features "$features" 1>&2
echo "run.sh: build took $(( $(date +%s) - t0 )) s" >&2
exec ./target/release/hostas-peers "$@"
