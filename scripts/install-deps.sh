#!/usr/bin/env bash
# Installs what scanpress needs from Debian packages (skips apt-get entirely when everything is present).
set -euo pipefail
PKGS=(cmake ninja-build g++ pkg-config zstd libzstd-dev nlohmann-json3-dev libgtest-dev libbenchmark-dev
      libtbb-dev libopenvdb-dev libboost-iostreams-dev libembree-dev libpng-dev)
missing=()
for p in "${PKGS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO=sudo; fi
  echo "installing: ${missing[*]}"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi
