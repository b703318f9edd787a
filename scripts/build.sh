#!/usr/bin/env bash
# Configures and builds scanpress. Release in build/ by default; SANITIZE=1 builds Debug with ASan+UBSan in
# build-asan/ (libraries at -O1, tests at -Og; line tables only, -g1: what the sanitizers' reports need, and it
# compiles faster). Extra arguments go to cmake's configure step, whose output (what was found, what is not built) is
# shown.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ "${SANITIZE:-0}" = "1" ]; then
  dir=build-asan
  cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG=-g1 -DSCANPRESS_SANITIZE=ON "$@"
else
  dir=build
  cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=Release "$@"
fi
cmake --build "$dir" -j "$(nproc)"
