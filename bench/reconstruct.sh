#!/usr/bin/env bash
# What the reference reconstruction costs against the run it reads: the wall time of `spadgen reconstruct`
# with each detector against `spadgen run` on the same scene, alternated in one session (PASSES times), and
# the ratios. Default: the multi-object scene (pixel-A half, 1024 x 500, 351 gate positions) at its 16 spp.
#
#   bench/reconstruct.sh [SPADGEN] [WORK_DIR] [PASSES]
set -euo pipefail
bin=$(realpath "${1:-build/app/spadgen}")
work=${2:-$(mktemp -d)}
passes=${3:-2}
cd "$(dirname "$0")/.."
scene=scenes/paper/multi_object.json

source bench/seconds.sh

echo "load: $(cut -d' ' -f1-3 /proc/loadavg)"
for pass in $(seq "$passes"); do
  r=$(seconds "$bin" run "$scene" -q -o "$work/run")
  p=$(seconds "$bin" reconstruct "$work/run" --detector paper -q)
  e=$(seconds "$bin" reconstruct "$work/run" --detector edges -q)
  echo "pass $pass: run $r s, reconstruct --detector paper $p s, --detector edges $e s; paper / run $(awk -v a="$p" -v b="$r" 'BEGIN { printf "%.2f", a / b }'), edges / run $(awk -v a="$e" -v b="$r" 'BEGIN { printf "%.2f", a / b }')"
done
