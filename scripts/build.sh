#!/usr/bin/env bash
# Configures and builds scanpress. Release in build/ by default; SANITIZE=1 builds Debug (at -O1) with ASan+UBSan in
# build-asan/. Extra arguments go to cmake's configure step, whose output (what was found, what is not built) is
# shown.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${SANITIZE:-0}" = "1" ]; then
  dir=build-asan
  cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DSCANPRESS_SANITIZE=ON "$@"
else
  dir=build
  cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@"
fi
cmake --build "$dir" -j "$(nproc)"
