#!/usr/bin/env bash
# Compares the outputs of two spadgen binaries, file by file, on every shipped scene and a few variants
# (crops with frames and transients, full_chip, dual exposure). A refactoring that must not change the
# data passes when every file is byte-identical; metadata.json is compared without its "run" section
# (wall time, threads), which says how a run went, not what it produced.
#
#   bench/compare_outputs.sh OLD_SPADGEN NEW_SPADGEN [WORK_DIR]
#
# Prints one line per run and file that differs, then "N passed, N failed" (runs). Exit 1 on any difference.
set -euo pipefail
if [ $# -lt 2 ]; then
  echo "usage: $0 OLD_SPADGEN NEW_SPADGEN [WORK_DIR]" >&2
  exit 2
fi
old=$(realpath "$1")
new=$(realpath "$2")
work=${3:-$(mktemp -d)}
cd "$(dirname "$0")/.."

# name | scene file | extra arguments
runs=(
  "flat_target|scenes/paper/flat_target.json|"
  "flat_target_far|scenes/paper/flat_target.json|--set camera.position_m=[0,0,1.6] --set camera.crop=[400,150,128,64]"
  "multi_object|scenes/paper/multi_object.json|"
  "multi_object_frames|scenes/paper/multi_object.json|--set camera.crop=[500,234,40,16] --set outputs.frames=true --set outputs.transient=true --set render.split_direct_indirect=true"
  "multi_object_full_chip|scenes/paper/multi_object.json|--set sensor.preset=full_chip --set camera.height_px=1000 --set camera.crop=[480,480,64,40]"
  "test_chart|scenes/paper/test_chart.json|"
  "test_chart_dual|scenes/paper/test_chart_dual.json|"
)

# metadata.json without the "run" section, keys sorted.
strip_meta() {
  python3 -c 'import json,sys; m=json.load(open(sys.argv[1])); m.pop("run",None); print(json.dumps(m,sort_keys=True,indent=1))' "$1"
}

passed=0
failed=0
for r in "${runs[@]}"; do
  IFS='|' read -r name scene extra <<<"$r"
  for side in old new; do
    bin=$old
    [ "$side" = new ] && bin=$new
    rm -rf "$work/$side/$name"
    # shellcheck disable=SC2086
    "$bin" run "$scene" -o "$work/$side/$name" -q $extra
  done
  diffs=0
  while IFS= read -r f; do
    a="$work/old/$name/$f"
    b="$work/new/$name/$f"
    if [ ! -f "$b" ]; then
      echo "$name: $f: missing in the new output"
      diffs=$((diffs + 1))
    elif [ "$f" = metadata.json ]; then
      if ! cmp -s <(strip_meta "$a") <(strip_meta "$b"); then
        echo "$name: metadata.json differs:"
        diff <(strip_meta "$a") <(strip_meta "$b") | head -20 || true
        diffs=$((diffs + 1))
      fi
    elif ! cmp -s "$a" "$b"; then
      echo "$name: $f differs"
      diffs=$((diffs + 1))
    fi
  done < <(cd "$work/old/$name" && find . -type f | sed 's|^\./||' | sort)
  extra_files=$(comm -13 <(cd "$work/old/$name" && find . -type f | sort) <(cd "$work/new/$name" && find . -type f | sort))
  if [ -n "$extra_files" ]; then
    echo "$name: files only in the new output: $extra_files"
    diffs=$((diffs + 1))
  fi
  if [ "$diffs" -eq 0 ]; then
    echo "$name: identical ($(cd "$work/new/$name" && find . -type f | wc -l) files)"
    passed=$((passed + 1))
  else
    failed=$((failed + 1))
  fi
done
echo "$passed passed, $failed failed"
[ "$failed" -eq 0 ]
