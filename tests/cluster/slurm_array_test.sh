#!/usr/bin/env bash
# A throw-away one-node Slurm (issue 23 part 5): munged, slurmctld and slurmd started in the foreground as root with
# their state in a temp directory and loopback ports, stopped by PID at the end. On it, the archive template
# (configs/slurm-array.sbatch) runs a 4-task array over a synthetic archive, then the merge job after it
# (afterany); the containers and the merged summary's per-file results must equal a single-process run's.
#
# usage: slurm_array_test.sh SCANPRESS_BINARY REPO_DIR
# Exits 0 on success, 1 on a failed check, 77 (ctest: skipped) with the reason when Slurm or munge is missing or
# its daemons cannot start here.
set -uo pipefail
bin=$(realpath "$1")
repo=$(realpath "$2")
skip() {
  echo "SKIPPED: $*"
  exit 77
}
fail() {
  echo "FAILED: $*"
  for f in "$work"/*.log; do
    [ -f "$f" ] && { echo "--- $f"; tail -20 "$f"; }
  done
  exit 1
}
for tool in munged mungekey slurmctld slurmd sbatch squeue sinfo; do
  command -v "$tool" >/dev/null || skip "$tool is not installed (scripts/install-test-tools.sh installs slurm-wlm and munge)"
done
[ "$(id -u)" = 0 ] || skip "the throw-away Slurm runs its daemons as root; this is not root"

work=$(mktemp -d /tmp/scanpress-slurm-XXXXXX)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  for p in "${pids[@]}"; do
    for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
    kill -9 "$p" 2>/dev/null
  done
  [ -n "${KEEP:-}" ] || rm -rf "$work"
}
trap cleanup EXIT

# Two free loopback ports (the kernel picks them).
read -r ctld_port slurmd_port < <(python3 -c '
import socket
s=[socket.socket() for _ in range(2)]
[x.bind(("127.0.0.1",0)) for x in s]
print(*[x.getsockname()[1] for x in s])')

mkdir -p "$work/state" "$work/spool" "$work/archive" "$work/ref" "$work/run"
mungekey -c -k "$work/munge.key" >/dev/null 2>&1 || skip "mungekey could not create a key"
chmod 600 "$work/munge.key"
munged -F -f -S "$work/munge.socket" --key-file "$work/munge.key" --pid-file "$work/munged.pid" \
  --log-file "$work/munged.log" --seed-file "$work/munge.seed" >"$work/munged.out.log" 2>&1 &
pids+=($!)
for _ in $(seq 50); do [ -S "$work/munge.socket" ] && break; sleep 0.1; done
[ -S "$work/munge.socket" ] || skip "munged did not start: $(tail -3 "$work/munged.out.log" "$work/munged.log" 2>/dev/null | tr '\n' ' ')"

cat >"$work/slurm.conf" <<EOF
ClusterName=scanpress-test
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$work/munge.socket
StateSaveLocation=$work/state
SlurmdSpoolDir=$work/spool
SlurmctldPidFile=$work/slurmctld.pid
SlurmdPidFile=$work/slurmd.pid
SlurmctldLogFile=$work/slurmctld.log
SlurmdLogFile=$work/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MailProg=/bin/true
ReturnToService=2
SchedulerType=sched/builtin
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$(nproc) RealMemory=1000 State=UNKNOWN
PartitionName=test Nodes=localhost Default=YES MaxTime=INFINITE State=UP OverSubscribe=FORCE:4
EOF
export SLURM_CONF=$work/slurm.conf
slurmctld -D -i -f "$SLURM_CONF" >"$work/slurmctld.out.log" 2>&1 &
pids+=($!)
slurmd -D -N localhost -f "$SLURM_CONF" >"$work/slurmd.out.log" 2>&1 &
pids+=($!)
ready=0
for _ in $(seq 150); do
  state=$(sinfo -h -N -o '%T' 2>/dev/null | head -1)
  case "$state" in idle* | mixed* | allocated*) ready=1 && break ;; esac
  sleep 0.2
done
[ "$ready" = 1 ] || skip "the throw-away Slurm did not come up (node state '${state:-none}'): $(tail -2 "$work"/slurm*.log 2>/dev/null | tr '\n' ' ')"

# The archive: five synthetic scans of different sizes (the split is balanced by file size).
for i in 1 2 3 4 5; do
  "$bin" synth "$work/archive/scan$i.ply" --triangles $((i * 7000)) --seed "$i" --quiet || fail "synth"
done
job() {
  cat <<EOF
{"inputs": ["$work/archive"], "output": {"directory": "$1"}, "codec": {"name": "edgebreaker"}}
EOF
}
job "$work/ref" >"$work/ref.json"
job "$work/run" >"$work/run.json"
"$bin" run "$work/ref.json" --quiet || fail "the single-process run"

# The array, as the template submits it (4 tasks of one CPU here), then the merge after every task.
export PATH="$(dirname "$bin"):$PATH"
cd "$work" || fail "cd"
jid=$(sbatch --parsable --array=0-3 --cpus-per-task=1 --mem=100M "$repo/configs/slurm-array.sbatch" "$work/run.json") ||
  fail "sbatch of the array"
mid=$(sbatch --parsable --dependency=afterany:"$jid" --cpus-per-task=1 --mem=100M --output="$work/merge-%j.log" \
  --wrap "$bin run $work/run.json --merge") || fail "sbatch of the merge"
# Poll squeue (sbatch --wait polls every 10 s).
for _ in $(seq 600); do
  [ -z "$(squeue -h -j "$jid,$mid" 2>/dev/null)" ] && break
  sleep 0.2
done
[ -z "$(squeue -h -j "$jid,$mid" 2>/dev/null)" ] && echo "array $jid and merge $mid ended" || fail "jobs still queued"
for t in 0 1 2 3; do
  [ -f "$work/scanpress-${jid}_$t.log" ] || fail "no log of array task $t"
done
[ -f "$work/run/summary.json" ] || fail "the merge wrote no summary.json: $(cat "$work"/merge-*.log)"

# Every container byte for byte the single-process run's; the merged summary lists every input, all ok.
for i in 1 2 3 4 5; do
  cmp -s "$work/ref/scan$i.spz" "$work/run/scan$i.spz" || fail "scan$i.spz differs from the single-process run's"
done
python3 - "$work/ref/summary.json" "$work/run/summary.json" <<'EOF' || fail "the merged summary differs"
import json, sys
ref, run = (json.load(open(p)) for p in sys.argv[1:])
key = lambda f: f["input"]
a = sorted(ref["files"], key=key)
b = sorted(run["files"], key=key)
assert len(b) == 5, f"{len(b)} files in the merged summary"
for x, y in zip(a, b):
    assert x["input"] == y["input"] and x["status"] == y["status"] == "ok", (x, y)
    assert x["bytes"] == y["bytes"], (x["input"], x["bytes"], y["bytes"])
import glob, os
shards = sorted(glob.glob(os.path.join(os.path.dirname(sys.argv[2]), "summary.shard-*-of-4.json")))
assert len(shards) == 4, shards
done = [f["input"] for s in shards for f in json.load(open(s))["files"] if f["status"] == "ok"]
assert sorted(done) == sorted(map(key, a)), ("each input encoded once, by one task", done)
print("merged summary: 5 files ok, bytes as the single-process run's; each encoded by exactly one of 4 tasks")
EOF
echo "PASSED: a 4-task Slurm array and its merge job give the single-process run's containers and summary"
