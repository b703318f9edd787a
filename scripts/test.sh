#!/usr/bin/env bash
# Installs dependencies, builds, and runs every test through ctest. SANITIZE=1 runs them under ASan+UBSan.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/install-test-tools.sh
# scanpress-mpi (mpi/) in the Release build when OpenMPI is there (install-test-tools.sh installs it).
mpi=()
if [ "${SANITIZE:-0}" != "1" ] && command -v mpicxx >/dev/null; then mpi=(-DSCANPRESS_MPI=ON); fi
bash scripts/build.sh "${mpi[@]}"
dir=build
if [ "${SANITIZE:-0}" = "1" ]; then dir=build-asan; fi
ctest --test-dir "$dir" --output-on-failure -j "$(nproc)"
