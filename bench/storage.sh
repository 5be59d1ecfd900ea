#!/usr/bin/env bash
# Storage of a 1-megapixel sample (issue 10): bytes of each output as .npy and as Zarr stores
# (outputs.storage), bytes of the EXR images per compression, the sample's total for each way of keeping
# its noise-free ground truth, and the wall time of whole runs with Zarr against .npy, alternated.
#
#   bench/storage.sh [SPADGEN] [WORK_DIR] [PAIRS] [-- EXTRA --set ARGUMENTS]
#
# Default: build/app/spadgen, a temporary folder, 3 passes (0: the sizes alone), the multi-object scene at 1024 x 1000 (the full
# chip, camera.height_px=1000), its 16 spp; EXTRA arguments go to every run (e.g. -- --set
# render.samples_per_pixel=4). Needs build/bench/exr_compression beside the program's build folder.
#
# 1. Sizes: one run per storage with every stack (counts, detection rate, expected counts, saved light, and
#    the transient and its indirect part over a 128 x 128 crop); bytes are the files' sizes.
# 2. Time: per pass, alternately, runs writing (A) counts and detection rate as .npy (today's default),
#    (B) the same as Zarr, (C) counts and the saved light as Zarr, no detection rate (the recommended
#    dataset sample), and (D) `spadgen sense` of a saved run writing counts and detection rate as .npy, then
#    (E) as Zarr: the sensor stage and the writing alone, without the renderer. Ratios of the summed times.
set -euo pipefail
bin=$(realpath "${1:-build/app/spadgen}")
work=${2:-$(mktemp -d)}
passes=${3:-3}
shift $(( $# < 3 ? $# : 3 )) || true
[ "${1:-}" = "--" ] && shift
extra=("$@")
exr_tool=$(dirname "$bin")/../bench/exr_compression
cd "$(dirname "$0")/.."
scene=scenes/paper/multi_object.json
base=(--set camera.height_px=1000 "${extra[@]}")
mkdir -p "$work"

bytes() { find "$@" -type f -printf '%s\n' 2>/dev/null | awk '{ s += $1 } END { printf "%d", s }'; }
mb() { awk -v b="$1" 'BEGIN { printf "%.1f", b / 1e6 }'; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.3f", a / b }'; }
add() { awk -v a="$1" -v b="$2" 'BEGIN { print a + b }'; }
timed() {  # wall seconds and peak resident MB of a command: "S MB"
  /usr/bin/time -f "%e %M" -o "$work/time.txt" "$@" > /dev/null 2>&1
  awk '{ printf "%.2f %.0f\n", $1, $2 / 1024 }' "$work/time.txt"
}

echo "# $(date -Iseconds), $(uptime | sed 's/.*load/load/'), $("$bin" --version 2>/dev/null | head -1)"
echo "# runs: $scene ${base[*]}"

# 1. Sizes
all=(--set outputs.expected_counts=true --set outputs.light=true --set outputs.transient=true
     --set render.split_direct_indirect=true --set "outputs.transient_crop=[448,436,128,128]")
for storage in npy zarr; do
  rm -rf "$work/size_$storage"
  "$bin" run "$scene" -q "${base[@]}" "${all[@]}" --set outputs.storage=$storage -o "$work/size_$storage"
done
echo
echo "| output | npy (MB) | zarr (MB) | zarr / npy |"
echo "|---|---|---|---|"
declare -A size
for out in counts detection_rate expected_counts transient transient_indirect light images; do
  for storage in npy zarr; do
    d=$work/size_$storage
    case $out in
      light) size[$out.$storage]=$(bytes "$d/light") ;;
      images) size[$out.$storage]=$(bytes "$d"/*.exr) ;;
      *) size[$out.$storage]=$(bytes "$d/$out.$storage") ;;
    esac
  done
  label=$out
  [ "$out" = transient ] || [ "$out" = transient_indirect ] && label="$out (128 x 128 crop)"
  [ "$out" = light ] && label="light/ (saved light, its eight arrays)"
  [ "$out" = images ] && label="EXR images (ground_truth, laser, ambient, sensor_maps, labels; zip)"
  echo "| $label | $(mb "${size[$out.npy]}") | $(mb "${size[$out.zarr]}") | $(ratio "${size[$out.zarr]}" "${size[$out.npy]}") |"
done
echo
echo "| sample: counts + noise-free ground truth + EXR images | MB |"
echo "|---|---|"
images=${size[images.npy]}
for s in npy zarr; do
  echo "| $s: counts + detection_rate | $(mb "$(add "$(add "${size[counts.$s]}" "${size[detection_rate.$s]}")" "$images")") |"
  echo "| $s: counts + light/ | $(mb "$(add "$(add "${size[counts.$s]}" "${size[light.$s]}")" "$images")") |"
done
if [ -x "$exr_tool" ]; then
  echo
  echo "EXR images of the .npy run rewritten per compression (bytes, fastest of 3 writes and reads, seconds):"
  "$exr_tool" "$work/size_npy" 3 | grep "all images"
fi
rm -rf "$work/size_zarr"
mv "$work/size_npy" "$work/saved"  # its light serves the sense passes

# 2. Time
declare -A sum
echo
for ((p = 1; p <= passes; ++p)); do
  rm -rf "$work/A" "$work/B" "$work/C" "$work/D" "$work/E"
  read -r a am < <(timed "$bin" run "$scene" -q "${base[@]}" -o "$work/A")
  read -r b bm < <(timed "$bin" run "$scene" -q "${base[@]}" --set outputs.storage=zarr -o "$work/B")
  read -r c cm < <(timed "$bin" run "$scene" -q "${base[@]}" --set outputs.storage=zarr --set outputs.light=true \
                   --set outputs.detection_rate=false -o "$work/C")
  read -r d dm < <(timed "$bin" sense "$work/saved" -q --set outputs.expected_counts=false -o "$work/D")
  read -r e em < <(timed "$bin" sense "$work/saved" -q --set outputs.expected_counts=false --set outputs.storage=zarr -o "$work/E")
  echo "pass $p ($(uptime | sed 's/.*average: //')): A npy counts+rate $a s ${am} MB | B zarr counts+rate $b s ${bm} MB |" \
       "C zarr counts+light $c s ${cm} MB | D sense npy $d s ${dm} MB | E sense zarr $e s ${em} MB"
  for k in a b c d e; do sum[$k]=$(add "${sum[$k]:-0}" "${!k}"); done
done
[ "$passes" -gt 0 ] || { rm -rf "$work/saved" "$work/time.txt"; exit 0; }  # sizes only
echo "run, zarr / npy (counts + detection_rate, B / A): $(ratio "${sum[b]}" "${sum[a]}")"
echo "run, zarr counts + light / npy counts + detection_rate (C / A): $(ratio "${sum[c]}" "${sum[a]}")"
echo "sense, zarr / npy (counts + detection_rate, E / D): $(ratio "${sum[e]}" "${sum[d]}")"
echo "written: A $(mb "$(bytes "$work/A")") MB, B $(mb "$(bytes "$work/B")") MB, C $(mb "$(bytes "$work/C")") MB"
rm -rf "$work/A" "$work/B" "$work/C" "$work/D" "$work/E" "$work/saved" "$work/time.txt"
