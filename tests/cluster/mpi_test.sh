#!/usr/bin/env bash
# One scan over the ranks of an MPI job (issue 23 part 2): scanpress-mpi at 3 and 4 ranks (mpirun on this machine,
# --oversubscribe --bind-to none) must write the container `scanpress` writes, byte for byte: several codecs,
# worker threads set or not, more ranks than tiles, a subset, an error target (the target search encodes several
# times), and a job file over two scans. A missing input fails with rank 0's message and a non-zero exit, and no
# rank is left waiting. Every mpirun is under a timeout: a deadlock fails the test instead of hanging it.
#
# usage: mpi_test.sh SCANPRESS_BINARY SCANPRESS_MPI_BINARY
# Exits 0 on success, 1 on a failed check, 77 (ctest: skipped) with the reason when scanpress-mpi is not built or
# mpirun cannot start here.
set -uo pipefail
skip() {
  echo "SKIPPED: $*"
  exit 77
}
bin=$(realpath "$1")
[ -n "${2:-}" ] && [ -x "$2" ] ||
  skip "scanpress-mpi is not in this build (a Release build with -DSCANPRESS_MPI=ON, as scripts/test.sh configures when OpenMPI is installed; never the sanitizer build)"
mpi=$(realpath "$2")
command -v mpirun >/dev/null || skip "mpirun is not installed (scripts/install-test-tools.sh installs openmpi-bin)"
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_plm=isolated
# Quiet about the fabrics a container lacks.
export OMPI_MCA_btl=self,vader OMPI_MCA_btl_vader_single_copy_mechanism=none

work=$(mktemp -d /tmp/scanpress-mpi-XXXXXX)
trap '[ -n "${KEEP:-}" ] || rm -rf "$work"' EXIT
fail() {
  echo "FAILED: $*"
  [ -f "$work/mpirun.log" ] && tail -20 "$work/mpirun.log"
  exit 1
}
ranks() {  # ranks N ARGS...: scanpress-mpi at N ranks, its output in mpirun.log
  local n=$1
  shift
  timeout 300 mpirun -np "$n" --oversubscribe --bind-to none "$mpi" "$@" >"$work/mpirun.log" 2>&1
}
timeout 60 mpirun -np 2 --oversubscribe --bind-to none true >"$work/mpirun.log" 2>&1 ||
  skip "mpirun cannot start 2 ranks here: $(tail -3 "$work/mpirun.log" | tr '\n' ' ')"

"$bin" synth "$work/a.ply" --triangles 100000 --seed 3 --quiet || fail "synth a"
"$bin" synth "$work/b.ply" --triangles 60000 --seed 4 --quiet || fail "synth b"
"$bin" synth "$work/c.ply" --triangles 24000 --seed 5 --quiet || fail "synth c"

# same NAME RANKS ENCODE-OPTIONS...: scanpress and scanpress-mpi at RANKS write the same container of a.ply (of
# $scan.ply when scan is set)
same() {
  local name=$1 n=$2 input="$work/${scan:-a}.ply"
  shift 2
  "$bin" encode "$input" "$work/$name.local.spz" --quiet "$@" || fail "$name: scanpress encode"
  ranks "$n" encode "$input" "$work/$name.mpi$n.spz" --quiet "$@" || fail "$name: scanpress-mpi at $n ranks"
  cmp -s "$work/$name.local.spz" "$work/$name.mpi$n.spz" || fail "$name: the container at $n ranks differs"
  echo "ok: $name at $n ranks ($(stat -c %s "$work/$name.local.spz") bytes)"
}

same edgebreaker 3 --tile-triangles 8192
same edgebreaker 4 --tile-triangles 8192
same kdtree 3 --codec kdtree --tile-triangles 8192 --threads 1
same kdtree-24-bits 3 --codec kdtree --bits 24 --tile-triangles 8192  # 25 levels a tile
same pm 4 --codec pm --tile-triangles 8192
# Measured on the workers: the report's error and per-tile figures equal the single process's.
"$bin" encode "$work/a.ply" "$work/m.local.spz" --quiet --codec pm --tile-triangles 8192 --measure \
  --report "$work/m.local.json" || fail "measured: scanpress encode"
ranks 3 encode "$work/a.ply" "$work/m.mpi.spz" --quiet --codec pm --tile-triangles 8192 --measure \
  --report "$work/m.mpi.json" || fail "measured: scanpress-mpi at 3 ranks"
cmp -s "$work/m.local.spz" "$work/m.mpi.spz" || fail "measured: the container at 3 ranks differs"
python3 - "$work/m.local.json" "$work/m.mpi.json" <<'EOF' || fail "measured: the reports differ"
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:])
assert a["error"]["symmetric"]["samples"] > 0, "nothing measured"
assert a["error"] == b["error"], (a["error"], b["error"])
strip = lambda ts: [{k: v for k, v in t.items() if "second" not in k} for t in ts]
assert strip(a["tiles"]) == strip(b["tiles"]), "per-tile figures differ"
EOF
echo "ok: measured on the workers, same report figures"
same few-tiles 4 --tile-triangles 65536  # 2 tiles, 3 workers: one has none
same subset 3 --tile-triangles 8192 --subset 1/3
# The target search (pm's, per tile: 8 tiles) on the smallest scan: on b.ply it took 13 of the test's 25 s.
scan=c same target 3 --codec pm --tile-triangles 4096 --max-error 2e-4

# A job file over two scans: the workers serve one scan after the other.
mkdir -p "$work/in" "$work/ref" "$work/out"
cp "$work/a.ply" "$work/b.ply" "$work/in/"
for d in ref out; do
  echo "{\"inputs\": [\"$work/in\"], \"output\": {\"directory\": \"$work/$d\"}, \"tiling\": {\"target_triangles\": 8192}}" \
    >"$work/$d.json"
done
"$bin" run "$work/ref.json" --quiet || fail "scanpress run"
ranks 3 run "$work/out.json" --quiet || fail "scanpress-mpi run at 3 ranks"
for f in a b; do
  cmp -s "$work/ref/$f.spz" "$work/out/$f.spz" || fail "run: $f.spz differs"
done
echo "ok: a job file of two scans at 3 ranks"

# Rank 0 fails: the job ends with its message and exit code, the workers do not wait forever.
ranks 3 encode "$work/missing.ply" "$work/missing.spz" --quiet
code=$?
[ "$code" != 0 ] && [ "$code" != 124 ] || fail "a missing input: exit $code"
grep -q "missing.ply" "$work/mpirun.log" || fail "a missing input: the message does not name it"
[ ! -e "$work/missing.spz" ] || fail "a missing input left an output"
echo "ok: a missing input fails at 3 ranks (exit $code)"
echo "PASSED"
