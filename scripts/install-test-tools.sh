#!/usr/bin/env bash
# Optional tools some tests use to check outputs against independent truth: node with the Khronos glTF validator
# (npm package gltf-validator), headless Chromium (Debian `chromium`) that loads report.html, Slurm with munge for a
# throw-away one-node cluster, and OpenMPI for scanpress-mpi (tests/cluster/). Best effort: when they cannot be
# installed (no network), those tests skip and say why.
set -uo pipefail
source "$(dirname "$0")/lib.sh"
if ! command -v node >/dev/null; then
  (install_missing_packages nodejs npm) || echo "note: node could not be installed; glTF validation tests will skip"
fi
if command -v node >/dev/null && command -v npm >/dev/null &&
  ! NODE_PATH="$(npm root -g 2>/dev/null)" node -e "require('gltf-validator')" >/dev/null 2>&1; then
  timeout 300 npm install -g --no-fund --no-audit gltf-validator >/dev/null 2>&1 ||
    echo "note: npm could not install gltf-validator; glTF validation tests will skip"
fi
if ! command -v chromium >/dev/null; then
  (install_missing_packages chromium) || echo "note: chromium could not be installed; the report.html browser test will skip"
fi
if ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
  (install_missing_packages slurm-wlm munge) || echo "note: slurm-wlm or munge could not be installed; the Slurm test will skip"
fi
if ! command -v mpirun >/dev/null || ! command -v mpicxx >/dev/null; then
  (install_missing_packages openmpi-bin libopenmpi-dev) || echo "note: OpenMPI could not be installed; scanpress-mpi is not built and its test will skip"
fi
exit 0
