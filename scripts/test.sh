#!/usr/bin/env bash
# Installs dependencies, builds, and runs every test through ctest. SANITIZE=1 runs them under ASan+UBSan.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/install-test-tools.sh
bash scripts/build.sh
dir=build
if [ "${SANITIZE:-0}" = "1" ]; then dir=build-asan; fi
ctest --test-dir "$dir" --output-on-failure -j "$(nproc)"
