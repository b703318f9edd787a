#!/usr/bin/env bash
# Builds the libFuzzer targets (clang, ASan+UBSan, build-fuzz/) and runs each: first a replay of its whole corpus
# (tests/fuzz/corpus/<target>/), then SECONDS of fuzzing from that corpus. The targets run side by side, one per
# core.
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
# At -O1 (CMakeLists.txt) with line tables only: what the reports need, and a third quicker to compile than -O2 -g.
CC=clang CXX=clang++ cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-gline-tables-only -DNDEBUG" -DSCANPRESS_FUZZ=ON -DSCANPRESS_BUILD_TESTS=OFF \
  -DSCANPRESS_BUILD_BENCH=OFF
build_targets=()
for t in $targets; do build_targets+=("fuzz_$t"); done
cmake --build "$dir" -j "$(nproc)" --target "${build_targets[@]}"

mkdir -p "$dir/logs"
rm -f "$dir/logs/failed"
# Runs a fuzzer with its output in build-fuzz/logs/ (libFuzzer's progress lines and dictionary run to thousands of
# lines); prints the last lines, and lists the log in build-fuzz/logs/failed when it fails.
run_logged() {
  local t=$1 phase=$2 log="$dir/logs/$1.$2.log"
  shift 2
  if "$@" >"$log" 2>&1; then
    grep -E '^(Done|stat::)' "$log" || true
  else
    tail -n 30 "$log"
    echo "$log" >>"$dir/logs/failed"
    return 1
  fi
}
# One target: the replay of its corpus, then the fuzzing.
run_target() {
  local t=$1 corpus=tests/fuzz/corpus/$1 status=0
  mkdir -p "$dir/corpus/$t" "$dir/crashers/$t"
  # -malloc_limit_mb: no single allocation over 256 MiB (issue 18: no container under 1 MB may need more).
  local flags=(-rss_limit_mb=2048 -malloc_limit_mb=256 -timeout=10 -artifact_prefix="$dir/crashers/$t/"
    -print_final_stats=1 -seed="${SCANPRESS_FUZZ_SEED:-1}")
  echo "== fuzz_$t: replaying $(find "$corpus" -type f | wc -l) corpus files"
  run_logged "$t" replay "$dir/bin/fuzz_$t" "${flags[@]}" -runs=0 "$corpus" || status=1
  if [ "$seconds" -gt 0 ]; then
    echo "== fuzz_$t: fuzzing for $seconds s"
    run_logged "$t" fuzz "$dir/bin/fuzz_$t" "${flags[@]}" -max_total_time="$seconds" "$dir/corpus/$t" "$corpus" ||
      status=1
  fi
  return "$status"
}
# The targets run side by side, one per core (each fuzzer is one process on one core): the same seed and seconds
# per target as one after the other, in less wall time (a target may run somewhat fewer inputs in its seconds
# beside another). Each one's output is printed whole when it ends.
status=0
running=0
for t in $targets; do
  if [ "$running" -ge "$(nproc)" ]; then
    wait -n || status=1
    running=$((running - 1))
  fi
  (run_target "$t" >"$dir/logs/$t.out" 2>&1 && code=0 || code=$?
    cat "$dir/logs/$t.out"
    exit "$code") &
  running=$((running + 1))
done
while [ "$running" -gt 0 ]; do
  wait -n || status=1
  running=$((running - 1))
done
failed=()
if [ -f "$dir/logs/failed" ]; then mapfile -t failed <"$dir/logs/failed"; fi
if [ "$status" != 0 ]; then
  # Repeated at the end, where a CI log's tail shows it: which target failed, the report, the input.
  echo "fuzz.sh: a target failed; its input is in $dir/crashers/" >&2
  for f in "${failed[@]}"; do
    echo "---- $f: the report" >&2
    grep -E -A40 '^==[0-9]+==|^(ERROR|SUMMARY|INFO: Test unit|MS: |artifact_prefix)|runtime error|out-of-memory|timeout' \
      "$f" | head -60 >&2 || true
  done
  for c in "$dir"/crashers/*/*; do
    [ -f "$c" ] || continue
    echo "---- $c ($(stat -c %s "$c") bytes), base64:" >&2
    head -c 4096 "$c" | base64 -w 120 >&2
  done
fi
exit "$status"
