#!/usr/bin/env bash
# Cost per triangle from 10^6 up (issue 23's scale target): for each size, a synthetic scan is written to disk
# (`scanpress synth`, binary PLY), encoded under a memory budget and decoded back under the same budget. Prints a
# Markdown table: wall and CPU seconds, Mtri/s (wall), CPU microseconds per triangle, peak RSS of each command (the
# process's own VmHWM), and the most temporary disk the encode used (its scratch directory, sampled every second).
#
# usage: bench/scale.sh [-b BUDGET] [-t THREADS] [-c CODEC] [-w WORKDIR] N...
#   e.g. bench/scale.sh 1000000 10000000 100000000
# Defaults: budget 1G, 2 threads, edgebreaker, a directory under /tmp. The inputs stay in WORKDIR (reused when the
# same size is asked for again); outputs are removed after each size.
set -euo pipefail
repo=$(cd "$(dirname "$0")/.." && pwd)
bin=${SCANPRESS:-$repo/build/bin/scanpress}
budget=1G threads=2 codec=edgebreaker work=/tmp/scanpress-scale
while getopts "b:t:c:w:" o; do
  case $o in
    b) budget=$OPTARG ;;
    t) threads=$OPTARG ;;
    c) codec=$OPTARG ;;
    w) work=$OPTARG ;;
    *) exit 1 ;;
  esac
done
shift $((OPTIND - 1))
[ $# -gt 0 ] || { echo "usage: $0 [-b BUDGET] [-t THREADS] [-c CODEC] [-w WORKDIR] N..." >&2; exit 1; }
mkdir -p "$work/scratch"

# run LABEL CMD...: the command's wall and CPU seconds and peak RSS into $wall $cpu $peak (MiB).
run() {
  local label=$1
  shift
  local t0 t1
  t0=$(date +%s.%N)
  SCANPRESS_PEAK_RSS_FILE="$work/peak" /usr/bin/time -f "%U %S" -o "$work/time" "$@" >"$work/$label.log" 2>&1 ||
    { echo "$label failed:" >&2; tail -5 "$work/$label.log" >&2; exit 1; }
  t1=$(date +%s.%N)
  wall=$(awk -v a="$t1" -v b="$t0" 'BEGIN { print a - b }')
  cpu=$(awk '{print $1 + $2}' "$work/time")
  peak=$(awk '{printf "%.0f", $1 / 1048576}' "$work/peak")
}

echo "| triangles | input | encode wall | CPU | Mtri/s | CPU us/tri | peak RSS | temp disk | decode wall | CPU | Mtri/s | peak RSS |"
echo "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
for n in "$@"; do
  in="$work/synth-$n.ply"
  [ -f "$in" ] || "$bin" synth "$in" --triangles "$n" --quiet
  insize=$(stat -c %s "$in")
  # The scratch directory's size, sampled while the encode runs.
  : >"$work/disk"
  (while true; do du -sb "$work/scratch" 2>/dev/null | cut -f1 >>"$work/disk"; sleep 1; done) &
  sampler=$!
  run encode "$bin" encode "$in" "$work/out.spz" --codec "$codec" --threads "$threads" --memory-budget "$budget" \
    --scratch-dir "$work/scratch" --quiet
  kill $sampler
  wait $sampler 2>/dev/null || true
  ew=$wall ec=$cpu ep=$peak
  disk=$(sort -n "$work/disk" | tail -1)
  run decode "$bin" decode "$work/out.spz" "$work/out.ply" --memory-budget "$budget" --scratch-dir "$work/scratch" \
    --quiet
  awk -v n="$n" -v in_b="$insize" -v ew="$ew" -v ec="$ec" -v ep="$ep" -v disk="${disk:-0}" -v dw="$wall" -v dc="$cpu" \
    -v dp="$peak" 'BEGIN {
      printf "| %d | %.2f GB | %.1f s | %.1f s | %.2f | %.2f | %d MiB | %.2f GB | %.1f s | %.1f s | %.2f | %d MiB |\n",
        n, in_b / 1e9, ew, ec, n / ew / 1e6, ec / n * 1e6, ep, disk / 1e9, dw, dc, n / dw / 1e6, dp }'
  rm -f "$work/out.spz" "$work/out.ply"
done
