#!/usr/bin/env bash
# Bench-only peers for side-by-side comparisons (never needed by scanpress itself): CGAL, meshoptimizer, Draco,
# and gnuplot for the rate-distortion plots.
set -euo pipefail
source "$(dirname "$0")/lib.sh"
bash "$(dirname "$0")/install-deps.sh"
install_missing_packages libcgal-dev libmeshoptimizer-dev libdraco-dev gnuplot-nox
