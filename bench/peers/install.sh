#!/usr/bin/env bash
# Installs the system libraries the peer benchmark links against (Debian/Ubuntu, run as root).
# Idempotent: does nothing if Embree 3's development package is already installed.
set -euo pipefail
if dpkg -s libembree-dev >/dev/null 2>&1 && [ -e /usr/include/embree3/rtcore.h ]; then
    echo "libembree-dev already installed ($(dpkg-query -W -f='${Version}' libembree-dev))"
else
    if [ "$(id -u)" -ne 0 ]; then
        echo "install.sh: run as root (apt-get install libembree-dev)" >&2
        exit 1
    fi
    export DEBIAN_FRONTEND=noninteractive
    apt-get update
    apt-get install -y libembree-dev
fi
# The tinybvh shim is C++ built by the `cc` crate: it needs a C++ compiler.
command -v c++ >/dev/null 2>&1 || { echo "install.sh: no C++ compiler (apt-get install g++)" >&2; exit 1; }
# xz is used to read crown-pbrt-flat.ply.xz if present.
command -v xz >/dev/null 2>&1 || echo "install.sh: note: no 'xz' binary; .xz meshes are read with the Rust lzma decoder"
