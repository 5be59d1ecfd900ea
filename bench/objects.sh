#!/usr/bin/env bash
# The cost of the object-level ground truth (the renderer's split of the laser light by object, the object
# slots, labels.exr): a base binary and a new one alternated on a quarter of the multi-object scene, one
# thread (CPU time is steadier than wall time on a shared machine), in the gate sweep (render, sensor and
# labels) and in the intensity mode (no labels: the renderer's share). Prints each run's user CPU and wall
# seconds and the medians' ratios.
#
#   bench/objects.sh OLD_SPADGEN NEW_SPADGEN [PASSES] [WORK_DIR]
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 OLD_SPADGEN NEW_SPADGEN [PASSES] [WORK_DIR]" >&2
  exit 2
fi
old=$(realpath "$1")
new=$(realpath "$2")
passes=${3:-6}
work=${4:-$(mktemp -d)}
cd "$(dirname "$0")/.."
log="$work/times.txt"
: > "$log"
args=(scenes/paper/multi_object.json -q --threads 1 --set "camera.crop=[256,125,512,250]")
for _ in $(seq 1 "$passes"); do
  for mode in gate_sweep intensity; do
    for side in old new; do
      bin=$old
      [ "$side" = new ] && bin=$new
      /usr/bin/time -f "$mode $side %U %e $(cut -d' ' -f1 /proc/loadavg)" -a -o "$log" \
        "$bin" run "${args[@]}" --set acquisition.mode=$mode -o "$work/$side-$mode" > /dev/null 2>&1
      tail -1 "$log"
    done
  done
done
python3 - "$log" <<'PY'
import collections, statistics, sys
runs = collections.defaultdict(list)
for line in open(sys.argv[1]):
    mode, side, user, wall, _ = line.split()
    runs[mode, side].append((float(user), float(wall)))
for mode in ("gate_sweep", "intensity"):
    o, n = runs[mode, "old"], runs[mode, "new"]
    med = lambda r, i: statistics.median(x[i] for x in r)
    pairs = " ".join(f"{b[0] / a[0]:.3f}" for a, b in zip(o, n))
    print(f"{mode}: user {med(o, 0):.2f} -> {med(n, 0):.2f} s (x {med(n, 0) / med(o, 0):.3f}), "
          f"wall {med(o, 1):.2f} -> {med(n, 1):.2f} s (x {med(n, 1) / med(o, 1):.3f}); pairs (user) {pairs}")
PY
