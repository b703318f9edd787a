#!/usr/bin/env bash
# Installs dependencies, builds, and runs the main job (configs/archive.json: the bundled scan) or, given a mesh
# file as $1, encodes that one; then describes the container and decodes it back to PLY. Outputs go to out/.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/build.sh
if [ $# -eq 0 ]; then
  ./build/bin/scanpress run configs/archive.json --force
  ./build/bin/scanpress info out/archive/bun_zipper.spz
  ./build/bin/scanpress decode out/archive/bun_zipper.spz out/archive/bun_zipper.decoded.ply
  echo "report: out/archive/bun_zipper.report.json, summary: out/archive/summary.json"
else
  input="$1"
  name="$(basename "$input")"; name="${name%.zst}"; name="${name%.*}"
  mkdir -p out
  ./build/bin/scanpress encode "$input" "out/$name.spz" --report "out/$name.report.json"
  ./build/bin/scanpress info "out/$name.spz"
  ./build/bin/scanpress decode "out/$name.spz" "out/$name.decoded.ply"
  echo "report: out/$name.report.json"
fi
