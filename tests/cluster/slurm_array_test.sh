#!/usr/bin/env bash
# A real single-node Slurm cluster: starts munged, slurmctld and slurmd (Debian's slurm-wlm and munge) in a
# temporary folder with their own ports and socket, submits the shipped examples/slurm/dataset_array.sbatch
# as a 4-task job array on a small dataset, waits for it, and checks that the dataset equals a serial run
# byte for byte and that each task ran its own shard. Stops the daemons and removes everything afterwards.
#
#   tests/cluster/slurm_array_test.sh SPADGEN_BINARY SOURCE_DIR
#
# Needs root (the daemons) and the packages of .ci/install-deps; exits 77 (ctest: skipped) without them.
set -euo pipefail
BIN=$(readlink -f "$1")
SRC=$(readlink -f "$2")
if [ "$(id -u)" -ne 0 ]; then echo "SKIP: starting munged, slurmctld and slurmd needs root"; exit 77; fi
for p in munged slurmctld slurmd sbatch sinfo; do
  command -v "$p" >/dev/null || { echo "SKIP: $p is not installed (bash .ci/install-deps installs slurm-wlm and munge)"; exit 77; }
done

W=$(mktemp -d /tmp/spadgen-slurm.XXXXXX)
chmod 755 "$W"
cleanup() {
  for f in slurmd slurmctld munged; do
    [ -f "$W/$f.pid" ] && kill "$(cat "$W/$f.pid")" 2>/dev/null || true
  done
  sleep 0.5
  for f in slurmd slurmctld munged; do
    [ -f "$W/$f.pid" ] && kill -9 "$(cat "$W/$f.pid")" 2>/dev/null || true
  done
  rm -rf "$W"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*"
  for log in munged.log slurmctld.log slurmd.log; do [ -f "$W/$log" ] && { echo "--- $log"; tail -20 "$W/$log"; }; done
  exit 1
}

# munge: its own socket and pid file, the package's key.
mkdir -p "$W/munge"
chown munge:munge "$W/munge"
runuser -u munge -- munged --socket="$W/munge/munge.sock" --pid-file="$W/munge/munged.pid" \
  --log-file="$W/munge/munged.log" --seed-file="$W/munge/munged.seed" || fail "munged did not start"
ln -sf "$W/munge/munged.pid" "$W/munged.pid"

# Slurm: one node (this machine), ports of our own, state in $W.
host=$(hostname -s)
port=$((20000 + RANDOM % 20000))
mkdir -p "$W/state" "$W/spool"
cat > "$W/slurm.conf" <<CONF
ClusterName=spadgentest
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$W/munge/munge.sock
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
StateSaveLocation=$W/state
SlurmdSpoolDir=$W/spool
SlurmctldPidFile=$W/slurmctld.pid
SlurmdPidFile=$W/slurmd.pid
SlurmctldLogFile=$W/slurmctld.log
SlurmdLogFile=$W/slurmd.log
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName=$host NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$W/slurm.conf"
slurmctld -c -f "$SLURM_CONF" || fail "slurmctld did not start"
slurmd -f "$SLURM_CONF" || fail "slurmd did not start"
for i in $(seq 1 60); do
  state=$(sinfo -h -o %T 2>/dev/null | head -1 || true)
  [ "$state" = "idle" ] && break
  sleep 0.5
done
[ "$state" = "idle" ] || fail "the node is not idle after 30 s (state: '$state')"
echo "slurm up: node $host idle (controller port $port)"

# A small dataset: 6 samples of a crop of the multi-object scene, 2 realisations of the noise each.
cat > "$W/dataset.json" <<JSON
{
  "description": "Slurm job array test", "seed": 5,
  "scenes": ["$SRC/scenes/paper/multi_object.json"],
  "samples": 6,
  "set": {"render.samples_per_pixel": 2, "acquisition.gate_sweep.stop_ns": 4.2, "camera.crop": [496, 232, 24, 20]},
  "grid": {"laser.average_power_mW": [1, 2]},
  "random": {"ambient.illuminance_lux": {"log_uniform": [1, 1000]}},
  "seeds": {"chip": 1}, "repeats": 2
}
JSON
"$BIN" dataset run "$W/dataset.json" -o "$W/serial" -q || fail "the serial run failed"

# The shipped sbatch script as a 4-task array, one core per task, as a user submits it.
cd "$W"
SPADGEN="$BIN" sbatch --wait --array=0-3 --cpus-per-task=1 --chdir="$W" \
  "$SRC/examples/slurm/dataset_array.sbatch" "$W/dataset.json" "$W/cluster" > "$W/sbatch.out" 2>&1 \
  || { cat "$W/sbatch.out"; cat "$W"/spadgen-dataset-*.out 2>/dev/null; fail "the job array failed"; }
cat "$W/sbatch.out"
outs=$(ls "$W"/spadgen-dataset-*_*.out | wc -l)
[ "$outs" -eq 4 ] || fail "expected the output of 4 array tasks, found $outs"
for i in 0 1 2 3; do
  grep -q "of shard $i/4 to generate" "$W"/spadgen-dataset-*_"$i".out || { cat "$W"/spadgen-dataset-*_"$i".out; fail "task $i did not run shard $i/4"; }
done
/usr/bin/python3 "$SRC/tests/cluster/compare_datasets.py" "$W/serial" "$W/cluster" || fail "the job array's dataset differs from the serial run"
"$BIN" dataset status "$W/cluster" | grep -q "6 samples: 6 done, 0 failed, 0 stale, 0 missing" || fail "status does not report 6 done"
echo "PASS: a 4-task Slurm job array wrote the serial run's dataset byte for byte"
