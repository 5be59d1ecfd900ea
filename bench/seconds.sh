# Sourced by the bench scripts: seconds CMD... runs a command quietly and prints its wall time in seconds.
# A command that fails prints its own output on stderr and makes seconds fail (with set -e, the script
# stops there rather than print a figure of a failed run).
seconds() {
  local t0 t1 out status=0
  out=$(mktemp)
  t0=$(date +%s.%N)
  "$@" > "$out" 2>&1 || status=$?
  t1=$(date +%s.%N)
  if [ "$status" -ne 0 ]; then
    echo "failed (exit $status): $*" >&2
    cat "$out" >&2
    rm -f "$out"
    return "$status"
  fi
  rm -f "$out"
  awk -v a="$t0" -v b="$t1" 'BEGIN { printf "%.2f", b - a }'
}
