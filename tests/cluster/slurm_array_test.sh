#!/usr/bin/env bash
# A real single-node Slurm cluster: starts munged, slurmctld and slurmd (Debian's slurm-wlm and munge) in a
# temporary folder with their own ports and socket by examples/slurm/local_slurm.sh, submits the shipped examples/slurm/dataset_array.sbatch
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
  "$SRC/examples/slurm/local_slurm.sh" stop "$W/slurm" 2>/dev/null || true
  rm -rf "$W"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*"
  for log in munged.log slurmctld.log slurmd.log; do [ -f "$W/slurm/$log" ] && { echo "--- $log"; tail -20 "$W/slurm/$log"; }; done
  exit 1
}

# The shipped one-machine Slurm (munged, slurmctld, slurmd in a folder of their own), as a user starts it.
"$SRC/examples/slurm/local_slurm.sh" start "$W/slurm" > "$W/slurm.env" || fail "examples/slurm/local_slurm.sh start failed"
grep -qx "export SLURM_CONF=$W/slurm/slurm.conf" "$W/slurm.env" || { cat "$W/slurm.env"; fail "start printed no SLURM_CONF line"; }
. "$W/slurm.env"
"$SRC/examples/slurm/local_slurm.sh" status "$W/slurm" | grep -q " idle " || fail "status does not say the node is idle"

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
