#!/usr/bin/env bash
# A single-node Slurm on this machine, for trying and testing experiments/slurm_shards.sh: munged,
# slurmctld and slurmd from Debian's slurm-wlm packages, all on localhost, with state and logs in one
# folder. Every command is idempotent.
#   scripts/slurm_local.sh [start]   install the packages if missing, write slurm.conf, start the
#                                    daemons, wait until sinfo shows the node idle
#   scripts/slurm_local.sh stop      cancel its jobs, stop the daemons (munged only if it started it)
#   scripts/slurm_local.sh status    sinfo and squeue; exit 1 when the controller does not answer
# Environment: RCB_SLURM_DIR (state, spool, logs, pid files; default ${TMPDIR:-/tmp}/rcb-slurm),
# RCB_SLURM_WAIT (seconds to wait for each daemon, default 60).
# The configuration goes to /etc/slurm/slurm.conf, where the Slurm commands look by default, unless a
# slurm.conf this script did not write is there: then it stays untouched and the configuration is
# written to $RCB_SLURM_DIR/slurm.conf, to be named by SLURM_CONF (the script says so).
# No cgroups (proctrack/linuxproc, task/none), no accounting database, no mail: it also runs in
# containers without systemd. The daemons listen on Slurm's ports 6817/6818 and only talk to localhost.
set -euo pipefail

command=${1:-start}
dir=${RCB_SLURM_DIR:-${TMPDIR:-/tmp}/rcb-slurm}
wait_seconds=${RCB_SLURM_WAIT:-60}
marker="# Written by rcbench scripts/slurm_local.sh"
packages=(slurm-wlm slurmctld slurmd slurm-client munge)

die() { echo "slurm_local: $*" >&2; exit 1; }
case "$command" in start | stop | status) ;; *) echo "slurm_local: unknown command '$command' (known: start, stop, status)" >&2; exit 2 ;; esac
if ! [[ $wait_seconds =~ ^[1-9][0-9]{0,4}$ ]]; then
  echo "slurm_local: RCB_SLURM_WAIT=$wait_seconds: expected whole seconds, 1 to 99999" >&2
  exit 2
fi

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"
  elif command -v sudo >/dev/null; then sudo "$@"
  else die "needs root for '$*' and sudo is not installed"; fi
}

# Which slurm.conf the daemons and the commands use (see the header).
conf=/etc/slurm/slurm.conf
if [ -e "$conf" ] && [[ "$(head -n 1 "$conf")" != "$marker"* ]]; then conf=$dir/slurm.conf; fi
if [ "$conf" != /etc/slurm/slurm.conf ]; then export SLURM_CONF=$conf; fi

# The pid in a pid file if that process is alive and is `name` (a stale file names another process).
live_pid() {
  local file=$1 name=$2 pid
  [ -r "$file" ] || return 1
  pid=$(tr -dc 0-9 <"$file")
  [ -n "$pid" ] && [ "$(cat "/proc/$pid/comm" 2>/dev/null)" = "$name" ] && echo "$pid"
}

# Sends SIGTERM to the daemon of a pid file and waits for it to exit (SIGKILL after the wait).
stop_daemon() {
  local file=$1 name=$2 pid i
  if ! pid=$(live_pid "$file" "$name"); then echo "slurm_local: $name is not running"; return 0; fi
  as_root kill -TERM "$pid"
  for ((i = 0; i < wait_seconds * 5; ++i)); do
    [ -d "/proc/$pid" ] || { echo "slurm_local: stopped $name (pid $pid)"; return 0; }
    sleep 0.2
  done
  echo "slurm_local: $name (pid $pid) ignored SIGTERM for ${wait_seconds}s; sending SIGKILL" >&2
  as_root kill -KILL "$pid" || true
}

# The node's state as sinfo prints it (idle, mixed, allocated, down*, ...), empty if no answer.
node_state() { timeout 5 sinfo -h -N -n localhost -o %T 2>/dev/null | head -n 1 || true; }

show_logs() {
  for f in "$dir/slurmctld.log" "$dir/slurmd.log"; do
    [ -r "$f" ] && { echo "--- last lines of $f"; tail -n 15 "$f"; }
  done >&2
}

if [ "$command" = status ]; then
  command -v sinfo >/dev/null || die "Slurm is not installed (run scripts/slurm_local.sh)"
  [ -n "${SLURM_CONF:-}" ] && echo "SLURM_CONF=$SLURM_CONF"
  timeout 10 scontrol ping >/dev/null 2>&1 || die "the controller does not answer (configuration $conf)"
  sinfo -N -l
  squeue
  exit 0
fi

if [ "$command" = stop ]; then
  if command -v squeue >/dev/null && timeout 10 scontrol ping >/dev/null 2>&1; then
    jobs=$(timeout 10 squeue -h -o %A 2>/dev/null | sort -u | tr '\n' ' ' || true)
    if [ -n "${jobs// /}" ]; then
      echo "slurm_local: cancelling jobs $jobs"
      # shellcheck disable=SC2086  # one argument per job id
      as_root scancel $jobs || true
      for ((i = 0; i < wait_seconds; ++i)); do
        [ -z "$(timeout 10 squeue -h -o %A 2>/dev/null || true)" ] && break
        sleep 1
      done
    fi
  fi
  stop_daemon "$dir/slurmd.pid" slurmd
  stop_daemon "$dir/slurmctld.pid" slurmctld
  if [ -e "$dir/munged.ours" ]; then
    stop_daemon /run/munge/munged.pid munged
    as_root rm -f "$dir/munged.ours"
  else
    echo "slurm_local: leaving munged alone (this script did not start it)"
  fi
  exit 0
fi

# --- start ---
t0=$SECONDS
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "slurm_local: installing ${missing[*]}"
  as_root apt-get update -qq
  as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
t_packages=$((SECONDS - t0))

# munge: the key (the package usually makes it), then the daemon, as the munge user.
if [ ! -e /etc/munge/munge.key ]; then
  as_root mungekey --create --keyfile=/etc/munge/munge.key
  as_root chown munge:munge /etc/munge/munge.key
  as_root chmod 0400 /etc/munge/munge.key
fi
as_root mkdir -p "$dir/state" "$dir/spool"
munge_ok() { munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; }
if ! munge_ok; then
  as_root mkdir -p /run/munge
  as_root chown munge:munge /run/munge
  as_root chmod 0755 /run/munge
  as_root runuser -u munge -- /usr/sbin/munged
  as_root touch "$dir/munged.ours"
  deadline=$((SECONDS + wait_seconds))
  until munge_ok || ((SECONDS >= deadline)); do sleep 0.2; done
  munge_ok || die "munged did not start within ${wait_seconds}s (see /var/log/munge/munged.log)"
fi

# slurm.conf for this machine: one node, localhost, every CPU, 90% of the memory.
cpus=$(nproc)
memory_mb=$(awk '/^MemTotal:/ { printf "%d", $2 / 1024 * 0.9 }' /proc/meminfo)
new_conf=$(cat <<EOF
$marker: a single-node cluster on localhost.
ClusterName=rcbench
SlurmctldHost=localhost
SlurmUser=root
AuthType=auth/munge
CredType=cred/munge
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MailProg=/bin/true
SlurmctldPort=6817
SlurmdPort=6818
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$memory_mb State=UNKNOWN
PartitionName=local Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
)
if [ "$(cat "$conf" 2>/dev/null)" != "$new_conf" ]; then
  as_root mkdir -p "$(dirname "$conf")"
  printf '%s\n' "$new_conf" | as_root tee "$conf" >/dev/null
  if pid=$(live_pid "$dir/slurmctld.pid" slurmctld); then
    echo "slurm_local: slurm.conf changed; telling the running daemons"
    as_root scontrol reconfigure || true
  fi
fi

if pid=$(live_pid "$dir/slurmctld.pid" slurmctld); then
  echo "slurm_local: slurmctld already running (pid $pid)"
else
  as_root slurmctld -f "$conf" || { show_logs; die "slurmctld failed to start"; }
fi
# Bounded by a deadline (a command that hangs, e.g. on a port someone else holds, cannot stretch it).
controller_up() { timeout 5 scontrol ping 2>/dev/null | grep -q UP; }
# A daemon that died (it reports fatal errors in its log after forking) ends the wait early.
gone() { ((SECONDS - started >= 2)) && ! live_pid "$dir/$1.pid" "$1" >/dev/null; }
started=$SECONDS
deadline=$((SECONDS + wait_seconds))
until controller_up || ((SECONDS >= deadline)) || gone slurmctld; do sleep 0.2; done
controller_up || { show_logs; die "slurmctld does not answer after $((SECONDS - started))s (is port 6817 free?)"; }

if pid=$(live_pid "$dir/slurmd.pid" slurmd); then
  echo "slurm_local: slurmd already running (pid $pid)"
else
  as_root slurmd -f "$conf" -N localhost || { show_logs; die "slurmd failed to start"; }
fi
state=""
started=$SECONDS
deadline=$((SECONDS + wait_seconds))
while ((SECONDS < deadline)) && ! gone slurmd; do
  state=$(node_state)
  case "$state" in idle | mixed | allocated | completing) break ;; esac
  sleep 0.2
done
case "$state" in
  idle | mixed | allocated | completing) ;;
  *) show_logs; die "node localhost is '${state:-not listed}' after $((SECONDS - started))s, not idle (sinfo -R says why)" ;;
esac
echo "slurm_local: node localhost $state ($cpus CPUs, ${memory_mb} MB), packages ${t_packages}s, daemons $((SECONDS - t0 - t_packages))s"
echo "slurm_local: configuration $conf, state and logs in $dir"
if [ -n "${SLURM_CONF:-}" ]; then echo "slurm_local: another slurm.conf is in /etc/slurm; use: export SLURM_CONF=$conf"; fi
