#!/usr/bin/env bash
# Installs dependencies, builds, and runs the main job on the bundled scan (or on the mesh given as $1):
# encode to a container with a report, describe it, decode it back to PLY. Outputs go to out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
input="${1:-data/bun_zipper.ply.zst}"
name="$(basename "$input")"; name="${name%.zst}"; name="${name%.*}"
mkdir -p out
./build/bin/scanpress encode "$input" "out/$name.spz" --report "out/$name.report.json"
./build/bin/scanpress info "out/$name.spz"
./build/bin/scanpress decode "out/$name.spz" "out/$name.decoded.ply"
echo "report: out/$name.report.json"
