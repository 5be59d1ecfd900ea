#!/usr/bin/env bash
# Datasets: samples per hour and bytes per sample of the shipped example dataset
# (examples/datasets/multi_object_variations.json: 1024 x 500, 4 paths per pixel, 351 gates x 255 frames),
# for each storage of the stacks (outputs.storage: npy, zarr; and zarr with the saved light instead of the
# detection rates, the example's own), and the plan's estimate against the measured time.
#
#   bench/dataset.sh [SPADGEN] [WORK_DIR] [SAMPLES]
#
# Default: build/app/spadgen, a temporary folder, the example's first 8 samples (its 24 would need 23 GB
# with .npy stacks). Each storage gets a copy of the example with outputs.storage set and "samples" cut to
# SAMPLES; the same samples are generated in each. Prints one line per storage.
set -euo pipefail
bin=$(realpath "${1:-build/app/spadgen}")
work=$(realpath -m "${2:-$(mktemp -d)}")
samples=${3:-8}
cd "$(dirname "$0")/.."
example=$(realpath examples/datasets/multi_object_variations.json)
mkdir -p "$work"
# Each variant: its name and the outputs it writes (the example's own: zarr_light).
declare -A variants=(
  [npy]='"outputs.storage": "npy", "outputs.light": false, "outputs.detection_rate": true,'
  [zarr]='"outputs.storage": "zarr", "outputs.light": false, "outputs.detection_rate": true,'
  [zarr_light]='"outputs.storage": "zarr", "outputs.light": true, "outputs.detection_rate": false,'
)
for storage in npy zarr zarr_light; do
  file="$work/variations_$storage.json"
  # The example with its scene path made absolute, its outputs replaced by the variant's, fewer samples.
  sed -e "s|\"../../scenes/|\"$(dirname "$(dirname "$example")")/../scenes/|" \
      -e '/^ *"outputs\./d' \
      -e "s|\"set\": {|\"set\": {${variants[$storage]}|" \
      -e "s|\"samples\": [0-9]*|\"samples\": $samples|" "$example" > "$file"
  out="$work/out_$storage"
  rm -rf "$out"
  estimate=$("$bin" dataset plan "$file" | awk -F'time about ' '/^# total/ {split($2, a, " \\("); print a[1]}')
  t0=$(date +%s.%N)
  "$bin" dataset run "$file" -o "$out" -q
  t1=$(date +%s.%N)
  python3 - "$out" "$t0" "$t1" "$storage" "$estimate" <<'PY'
import json, sys
out, t0, t1, storage, estimate = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), sys.argv[4], sys.argv[5]
rows = [json.loads(l) for l in open(out + "/index.jsonl")]
done = [r for r in rows if r["status"] == "done"]
sec = t1 - t0
per = {}
for r in done:
    meta = json.load(open(f"{out}/{r['folder']}/metadata.json"))
    for f in r["files"]:
        import os
        p = f"{out}/{r['folder']}/{f}"
        size = sum(os.path.getsize(os.path.join(d, n)) for d, _, ns in os.walk(p) for n in ns) if os.path.isdir(p) else os.path.getsize(p)
        key = f.split("/")[0]
        per[key] = per.get(key, 0) + size
mean = sum(r["bytes"] for r in done) / len(done)
print(f"storage {storage}: {len(done)} samples in {sec:.1f} s = {3600 * len(done) / sec:.0f} samples per hour; "
      f"{mean / 1e6:.1f} MB per sample; plan estimated {estimate}")
for k, v in sorted(per.items(), key=lambda kv: -kv[1]):
    print(f"    {k}: {v / len(done) / 1e6:.2f} MB per sample")
PY
done
