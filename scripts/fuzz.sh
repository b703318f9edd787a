#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan+UBSan, build-fuzz/) and runs each: first a replay of its whole corpus
# (tests/fuzz/corpus/<target>/), then SECONDS of fuzzing from that corpus.
#
#   bash scripts/fuzz.sh [SECONDS]   seconds per target: the argument, else $SCANPRESS_FUZZ_SECONDS, else 60;
#                                    0 only replays
#   SCANPRESS_FUZZ_TARGETS="container mesh config"   the targets to run
#   SCANPRESS_FUZZ_SEED=N            libFuzzer's seed (default 1: CI explores the same inputs on every run, so a
#                                    submission does not fail on a crasher that an unrelated change happened to
#                                    draw; 0 lets libFuzzer pick one, for longer explorations)
#
# New inputs the fuzzer keeps go to build-fuzz/corpus/<target>/ (not into the repo); a crash, a sanitizer report, a
# timeout (10 s) or an allocation over 256 MiB leaves its input in build-fuzz/crashers/<target>/ and fails the
# script. A crasher becomes a corpus file for good: copy it to tests/fuzz/corpus/<target>/ with the fix (README,
# "Fuzzing").
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-${SCANPRESS_FUZZ_SECONDS:-60}}
targets=${SCANPRESS_FUZZ_TARGETS:-container mesh config}
source scripts/lib.sh
bash scripts/install-deps.sh
install_missing_packages clang libclang-rt-14-dev
dir=build-fuzz
CC=clang CXX=clang++ cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DSCANPRESS_FUZZ=ON \
  -DSCANPRESS_BUILD_TESTS=OFF -DSCANPRESS_BUILD_BENCH=OFF
build_targets=()
for t in $targets; do build_targets+=("fuzz_$t"); done
cmake --build "$dir" -j "$(nproc)" --target "${build_targets[@]}"

status=0
for t in $targets; do
  corpus=tests/fuzz/corpus/$t
  mkdir -p "$dir/corpus/$t" "$dir/crashers/$t"
  # -malloc_limit_mb: no single allocation over 256 MiB (issue 18: no container under 1 MB may need more).
  flags=(-rss_limit_mb=2048 -malloc_limit_mb=256 -timeout=10 -artifact_prefix="$dir/crashers/$t/" -print_final_stats=1
    -seed="${SCANPRESS_FUZZ_SEED:-1}")
  echo "== fuzz_$t: replaying $(find "$corpus" -type f | wc -l) corpus files"
  "$dir/bin/fuzz_$t" "${flags[@]}" -runs=0 "$corpus" || status=1
  if [ "$seconds" -gt 0 ]; then
    echo "== fuzz_$t: fuzzing for $seconds s"
    "$dir/bin/fuzz_$t" "${flags[@]}" -max_total_time="$seconds" "$dir/corpus/$t" "$corpus" || status=1
  fi
done
if [ "$status" != 0 ]; then
  echo "fuzz.sh: a target failed; its input is in $dir/crashers/" >&2
fi
exit "$status"
