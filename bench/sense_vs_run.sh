#!/usr/bin/env bash
# Render once, sample many: the wall time of `spadgen sense` (the sensor stage alone, from a run's saved
# light) against `spadgen run` (render + sensor) on the same scene, alternated in one session, and the cost
# of extra noise realisations (--repeats). Prints one line per measurement and the ratios.
#
#   bench/sense_vs_run.sh [SPADGEN] [WORK_DIR] [PASSES] [-- EXTRA --set ARGUMENTS]
#
# Default: build/app/spadgen, a temporary folder, 2 passes, the multi-object scene at 1024 x 1000 (the full
# chip), 16 spp. Each pass: run (with outputs.light); sense with the run's sensor (a new noise
# realisation: the noise-free files are the run's, linked); sense --repeats 2; sense with another chip
# (seeds.chip: every file computed and written again, the 1.4 GB float32 detection rates too); and that
# with the counts only (outputs.detection_rate=false), which separates the sensor's computation from
# writing the rates.
set -euo pipefail
bin=$(realpath "${1:-build/app/spadgen}")
work=${2:-$(mktemp -d)}
passes=${3:-2}
shift $(( $# < 3 ? $# : 3 )) || true
[ "${1:-}" = "--" ] && shift
extra=("$@")
cd "$(dirname "$0")/.."
scene=scenes/paper/multi_object.json
base=(--set camera.height_px=1000 "${extra[@]}")

source bench/seconds.sh

declare -A sum
for ((p = 1; p <= passes; ++p)); do
  rm -rf "$work/run" "$work/s1" "$work/s2" "$work/chip" "$work/c1"
  r=$(seconds "$bin" run "$scene" -q "${base[@]}" --set outputs.light=true -o "$work/run")
  s1=$(seconds "$bin" sense "$work/run" -q --noise-seed 2 -o "$work/s1")
  s2=$(seconds "$bin" sense "$work/run" -q --noise-seed 2 --repeats 2 -o "$work/s2")
  chip=$(seconds "$bin" sense "$work/run" -q --chip-seed 2 -o "$work/chip")
  c1=$(seconds "$bin" sense "$work/run" -q --chip-seed 2 --set outputs.detection_rate=false -o "$work/c1")
  echo "pass $p: run $r s | sense $s1 s, --repeats 2 $s2 s | another chip: sense $chip s, counts only $c1 s"
  for k in r s1 s2 chip c1; do sum[$k]=$(awk -v a="${sum[$k]:-0}" -v b="${!k}" 'BEGIN { print a + b }'); done
done
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.3f", a / b }'; }
diff() { awk -v a="$1" -v b="$2" 'BEGIN { print a - b }'; }
echo "sense / run: $(ratio "${sum[s1]}" "${sum[r]}")"
echo "extra realisation / sense: $(ratio "$(diff "${sum[s2]}" "${sum[s1]}")" "${sum[s1]}")"
echo "another chip: sense / run: $(ratio "${sum[chip]}" "${sum[r]}"), counts only: $(ratio "${sum[c1]}" "${sum[r]}")"
du -sh "$work/run/light" | awk '{print "saved light: " $1}'
rm -rf "$work/run" "$work/s1" "$work/s2" "$work/chip" "$work/c1"
