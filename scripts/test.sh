#!/usr/bin/env bash
# Installs dependencies, builds, and runs every test through ctest. SANITIZE=1 runs them under ASan+UBSan.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
bash scripts/install-test-tools.sh
# scanpress-mpi (mpi/) in the Release build when OpenMPI is there (install-test-tools.sh installs it).
# The sanitizer lane runs tests only: no benchmark programs to compile there (the Release lane builds them).
extra=()
if [ "${SANITIZE:-0}" != "1" ] && command -v mpicxx >/dev/null; then extra+=(-DSCANPRESS_MPI=ON); fi
if [ "${SANITIZE:-0}" = "1" ]; then extra+=(-DSCANPRESS_BUILD_BENCH=OFF); fi
bash scripts/build.sh "${extra[@]}"
dir=build
exclude=()
if [ "${SANITIZE:-0}" = "1" ]; then
  dir=build-asan
  # Under the sanitizers, two measurement-heavy families run in the Release build only, to keep CI within its
  # time: the error and size target searches (Targets.*: many pm encodes, decodes and measurements of the same
  # code the codec tests cover) and all 15 scans simplified to 10% (Data/SimplifyScans.*; test_simplify's ugly and
  # damaged meshes run here). Together about 950 s of the sanitizer suite's 3200. Also the two chunked
  # measure/render cases that only drive the binary over 200k-triangle scans (the same code runs here through the
  # library tests of test_chunked_surface.cpp). And the whole-scan remeshing runs (RemeshScans.*, PrmCodec.*: igea,
  # bunny and horse through relief construction, resampling and the prm coder, about 230 s here; the same code runs
  # here on the synthetic reliefs, spheres and tori of Resample.*, Remesh.* and Prm.*), the stage that moves every
  # unlocked vertex over real scans and the kill-and-resume batch (process-level, 34 s each).
  # The malformation sweep through the CLI (MalformationSweepCli: `scanpress decode` on mutated files, for its exit
  # codes) too: MalformationSweep.* runs the same decoders in-process here, and the fuzz lane under ASan as well.
  # And the tests that drive the binary over real scans or many processes, whose code the in-process tests run here
  # (a process start under ASan and TBB is slow): the commands on real scans (Scans/DataRoundTrip.ThroughFiles...,
  # 27 s here), the Slurm array, the streamed decode's CLI messages, stdin/stdout pipes and the interrupt test. And
  # the check that container read errors name the file and the place (26 s here: it builds the sweep's containers
  # and reads their mutations through every command path; its subject is the messages, which the Release lane
  # checks, while the sweep and the fuzz lane run the same decoders under ASan). And (2026-11-28, 65 s here) the glTF
  # outputs checked by the Khronos validator and the peers' decoders (other programs' code), `--codec auto` under
  # strict (pm searches, as Targets.*), prm on bunny with its scalars (whole-scan remeshing, as RemeshScans.*), and
  # the two CLI tests that drive the binary over every level and output format (the decoders and writers run here
  # in-process: Codecs/*, StreamDecode*).
  exclude=(-E '^(Targets\.|Data/SimplifyScans\.|ChunkedSurface\.(CliMeasures|JobErrorPicture)|RemeshScans\.|PrmCodec\.|Pipeline\.StageMovingEveryUnlockedVertex|Durability\.KilledAndResumed|MalformationSweepCli\.|Scans/DataRoundTrip\.ThroughFilesWithTheCommands/|Cluster\.SlurmArray|StreamDecodeCli\.|Cli\.StdinAndStdoutThroughPipes|Outputs\.InterruptRemovesTemporariesAndScratch|Container\.EveryReadErrorNamesTheFileAndAnOffsetOrATile|Gltf\.CompressedAndTiledOutputsValidate|ScalarFiles\.(AutoUnderStrictKeepsTheScalars|WhatIsDroppedIsSaid)|Cli\.ProgressiveDecodeByLevelAndBytes|Cli\.DecodeToEveryFormat)')
fi
# ctest starts the longest tests first when it knows their times (its cost file); a fresh build does not, and ran
# them in declaration order, with long tests left alone at the end. So a fresh build starts from the times of a
# committed run, which ctest then updates in the build directory (measured on the Release lane: 423 s in
# declaration order, 395 s longest first; many tests run two threads, so the suite is mostly CPU-bound on two
# cores). Refresh the committed files after a full run when tests change much:
#   cp build/Testing/Temporary/CTestCostData.txt tests/ctest-costs/release.txt (build-asan: asan.txt)
lane=release
if [ "${SANITIZE:-0}" = "1" ]; then lane=asan; fi
mkdir -p "$dir/Testing/Temporary"
if [ ! -f "$dir/Testing/Temporary/CTestCostData.txt" ]; then
  cp "tests/ctest-costs/$lane.txt" "$dir/Testing/Temporary/CTestCostData.txt"
fi
ctest --test-dir "$dir" --output-on-failure -j "$(nproc)" "${exclude[@]}"
