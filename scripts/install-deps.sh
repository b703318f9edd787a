#!/usr/bin/env bash
# Installs what scanpress needs from Debian packages (skips apt-get entirely when everything is present).
set -euo pipefail
source "$(dirname "$0")/lib.sh"
install_missing_packages cmake ninja-build g++ pkg-config zstd libzstd-dev nlohmann-json3-dev libgtest-dev \
  libbenchmark-dev libtbb-dev libopenvdb-dev libboost-iostreams-dev libembree-dev libpng-dev libdraco-dev \
  libmeshoptimizer-dev python3-dev python3-pybind11 python3-numpy python3-pytest
