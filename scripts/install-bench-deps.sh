#!/usr/bin/env bash
# Bench-only peers for side-by-side comparisons: CGAL, gltfpack (an anchor of the rate-distortion comparison) and
# gnuplot for its plots (meshoptimizer and Draco, peers too, are scanpress's own dependencies for glTF compression).
set -euo pipefail
source "$(dirname "$0")/lib.sh"
bash "$(dirname "$0")/install-deps.sh"
install_missing_packages libcgal-dev libmeshoptimizer-dev libdraco-dev gnuplot-nox gltfpack
