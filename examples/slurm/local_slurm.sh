#!/usr/bin/env bash
# A one-machine Slurm, to try the job arrays of this folder without a cluster: munged, slurmctld and slurmd
# (Debian 12: apt-get install slurm-wlm munge, which .ci/install-deps does) started as root in a folder of
# their own, with their own ports, munge socket, state and logs. Nothing under /etc is changed, and the
# machine's own munge and Slurm services, if any, are left alone.
#
#   examples/slurm/local_slurm.sh start DIR    # prints the line to run: export SLURM_CONF=DIR/slurm.conf
#   examples/slurm/local_slurm.sh status DIR   # the node's state (idle, allocated, ...)
#   examples/slurm/local_slurm.sh stop DIR     # stops the daemons; DIR keeps their logs
#
# One node, this machine, with all its cores, in one partition `local`. Its tests: tests/cluster/slurm_array_test.sh.
set -euo pipefail
usage() { echo "usage: $0 start|status|stop DIR" >&2; exit 2; }
[ $# -eq 2 ] || usage
cmd=$1
dir=$2
daemons="slurmd slurmctld munged"

running() {  # the daemon whose pid file is in DIR runs: that pid is a live process of its name (a stale pid
  # file, of a crash or a reboot, may name another process now), not exited and unreaped
  [ -f "$dir/$1.pid" ] || return 1
  local pid
  pid=$(cat "$dir/$1.pid" 2>/dev/null) || return 1
  case "$pid" in '' | *[!0-9]*) return 1 ;; esac
  [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$1" ] && ! grep -q '^State:[[:space:]]*Z' "/proc/$pid/status" 2>/dev/null
}

stop() {
  # the jobs first (their tasks would run on without the daemons)
  [ -f "$dir/slurm.conf" ] && running slurmctld && SLURM_CONF="$dir/slurm.conf" scancel --user="$(id -un)" 2>/dev/null || true
  for d in $daemons; do running "$d" && kill "$(cat "$dir/$d.pid")" 2>/dev/null || true; done
  for _ in $(seq 1 20); do
    alive=0
    for d in $daemons; do running "$d" && alive=1; done
    [ $alive -eq 0 ] && return 0
    sleep 0.25
  done
  for d in $daemons; do running "$d" && kill -9 "$(cat "$dir/$d.pid")" 2>/dev/null || true; done
  return 0
}

case "$cmd" in
  start) ;;
  status)
    [ -f "$dir/slurm.conf" ] || { echo "$dir: no slurm.conf (not started with '$0 start $dir')" >&2; exit 1; }
    for d in $daemons; do running "$d" || { echo "$d is not running (its log: $dir/$d.log)"; exit 1; }; done
    SLURM_CONF="$dir/slurm.conf" sinfo -h -o "%n %T %c"
    exit 0 ;;
  stop)
    [ -d "$dir" ] || { echo "$dir: no such folder" >&2; exit 1; }
    any=0
    for d in $daemons; do running "$d" && any=1; done
    if [ $any -eq 0 ]; then echo "nothing of $dir was running" >&2; exit 0; fi
    stop
    echo "stopped (logs in $dir)" >&2
    exit 0 ;;
  *) usage ;;
esac

if [ "$(id -u)" -ne 0 ]; then echo "$0: starting munged, slurmctld and slurmd needs root" >&2; exit 1; fi
for p in munged slurmctld slurmd sinfo runuser; do
  command -v "$p" >/dev/null || { echo "$0: $p is not installed (Debian 12: apt-get install slurm-wlm munge)" >&2; exit 1; }
done
for d in $daemons; do
  if running "$d"; then echo "$0: $d already runs from $dir (stop it first: $0 stop $dir)" >&2; exit 1; fi
done
case "$dir" in *[[:space:]]* | *\'* | *\"* | *\$* | *\\*)
  echo "$0: $dir: a folder whose path holds no spaces or quotes, please (it is written into slurm.conf)" >&2; exit 1 ;;
esac
mkdir -p "$dir"
dir=$(readlink -f "$dir")
chmod 755 "$dir"
if ! runuser -u munge -- test -x "$dir"; then
  echo "$0: the munge user cannot reach $dir (a parent folder is closed to other users); choose a folder under /tmp or /srv" >&2
  exit 1
fi
fail() {
  echo "$0: $*" >&2
  for log in munged.log slurmctld.log slurmd.log; do [ -f "$dir/$log" ] && { echo "--- $dir/$log" >&2; tail -20 "$dir/$log" >&2; }; done
  stop
  exit 1
}

# munge: its own socket, key copy and pid file (the package's key, readable by munge only).
mkdir -p "$dir/munge"
chown munge:munge "$dir/munge"
runuser -u munge -- munged --socket="$dir/munge/munge.sock" --pid-file="$dir/munge/munged.pid" \
  --log-file="$dir/munge/munged.log" --seed-file="$dir/munge/munged.seed" || fail "munged did not start"
ln -sf "$dir/munge/munged.pid" "$dir/munged.pid"
ln -sf "$dir/munge/munged.log" "$dir/munged.log"

# Slurm: one node (this machine), ports of its own, state in DIR.
host=$(hostname -s)
cpus=$(getconf _NPROCESSORS_ONLN)  # (nproc follows OMP_NUM_THREADS)
port=$((20000 + RANDOM % 20000))
mkdir -p "$dir/state" "$dir/spool"
cat > "$dir/slurm.conf" <<CONF
ClusterName=spadgenlocal
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
AuthType=auth/munge
AuthInfo=socket=$dir/munge/munge.sock
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=local Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF="$dir/slurm.conf"
slurmctld -c -f "$SLURM_CONF" || fail "slurmctld did not start"
slurmd -f "$SLURM_CONF" || fail "slurmd did not start"
state=
for _ in $(seq 1 60); do
  state=$(sinfo -h -o %T 2>/dev/null | head -1 || true)
  [ "$state" = "idle" ] && break
  sleep 0.5
done
[ "$state" = "idle" ] || fail "the node is not idle after 30 s (state: '$state')"
echo "slurm up: node $host idle, $cpus CPUs, controller port $port; stop it with: $0 stop $dir" >&2
echo "export SLURM_CONF=$SLURM_CONF"
