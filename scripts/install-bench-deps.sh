#!/usr/bin/env bash
# Bench-only peers for side-by-side comparisons (never needed by scanpress itself): CGAL, meshoptimizer, Draco,
# and gnuplot for the rate-distortion plots.
set -euo pipefail
bash "$(dirname "$0")/install-deps.sh"
PKGS=(libcgal-dev libmeshoptimizer-dev libdraco-dev gnuplot-nox)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
