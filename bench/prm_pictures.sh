#!/usr/bin/env bash
# Pictures of prm's remeshing (issue 21, part 7), as the paper's Fig. 1 and 10: each scan coded with
# `--codec prm` at 12 bits and the default lattice (grid 0.005; fandisk, a coarse CAD mesh that this lattice would
# make larger and prm therefore keeps as it is, at 0.01), drawn colored by relief (irregular faces white)
# and by regularity. Writes bench/pictures/prm-<scan>-{reliefs,regularity}.png.
# Usage: bench/prm_pictures.sh [BUILD_DIR] [DATA_DIR]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${1:-$here/../build}
data=${2:-$here/../../shared/data}
bin=$build/bin/scanpress
out=$here/pictures
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
mkdir -p "$out"
# scan, view (azimuth,elevation), lattice
while read -r scan view grid; do
  src=$(ls "$data/$scan".* | head -1)
  "$bin" encode "$src" "$work/$scan.spz" --codec prm --grid "$grid" --bits 12 --no-colors --no-normals --no-scalars \
    --quiet
  # Prints the faces and the regular share once.
  "$bin" render "$work/$scan.spz" "$out/prm-$scan-reliefs.png" --color-by reliefs --size 640,480 --view "$view"
  "$bin" render "$work/$scan.spz" "$out/prm-$scan-regularity.png" --color-by regularity --size 640,480 \
    --view "$view" >/dev/null
  echo "$scan: $(stat -c %s "$work/$scan.spz") bytes"
done <<'SCANS'
horse 90,10 0.005
bun_zipper 0,10 0.005
igea 0,10 0.005
armadillo 180,10 0.005
lucy 0,10 0.005
rs1_normals 0,10 0.005
turbineblade 30,20 0.005
fandisk 30,20 0.01
SCANS
