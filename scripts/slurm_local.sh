#!/usr/bin/env bash
# A one-node SLURM cluster on localhost (munge, MariaDB, slurmdbd, slurmctld, slurmd), for tests and
# for trying the SLURM launcher. No systemd: every daemon runs from a private folder and is stopped by
# the PID it recorded, never by name.
#
#   scripts/slurm_local.sh up          install missing Debian packages (root), start the daemons, wait
#                                      until the node is idle, print the `export SLURM_CONF=...` line
#   scripts/slurm_local.sh env         print `export SLURM_CONF=...` (use: eval "$(scripts/slurm_local.sh env)")
#   scripts/slurm_local.sh status      which daemons run (exit 1 if not all)
#   scripts/slurm_local.sh down        cancel this cluster's jobs, stop the daemons (state is kept)
#   scripts/slurm_local.sh down --purge   ... and delete the private folder
#
# Settings: REPRO_SLURM_DIR (default /tmp/taco-slurm), REPRO_SLURM_PORT_BASE (default 16817: slurmctld,
# then slurmd, slurmdbd, MariaDB on the next three ports), REPRO_SLURM_GPUS (default 0: the number of stand-in
# GPUs the node declares as GRES `gpu`: character devices $REPRO_SLURM_DIR/dev/nvidia0.. (made with mknod, as root)
# named by gres.conf's File=, so jobs asking for GPUs are scheduled on the node and get CUDA_VISIBLE_DEVICES; no
# real GPU behind them).
# `up` and `down` are idempotent; `up` with other settings than the running cluster's restarts slurmctld and slurmd.
set -euo pipefail

DIR=${REPRO_SLURM_DIR:-/tmp/taco-slurm}
PORT_BASE=${REPRO_SLURM_PORT_BASE:-16817}
CTLD_PORT=$PORT_BASE
SLURMD_PORT=$((PORT_BASE + 1))
DBD_PORT=$((PORT_BASE + 2))
DB_PORT=$((PORT_BASE + 3))
HOST=$(hostname -s)
GPUS=${REPRO_SLURM_GPUS:-0}
[[ $GPUS =~ ^[0-9]+$ ]] || { echo "slurm_local: REPRO_SLURM_GPUS must be a number (got '$GPUS')" >&2; exit 2; }
PKGS=(slurmctld slurmd slurm-client munge slurmdbd mariadb-server)
DAEMONS=(munged mariadbd slurmdbd slurmctld slurmd)   # start order; stopped in reverse
export SLURM_CONF=$DIR/etc/slurm.conf

log() { echo "slurm_local: $*" >&2; }
die() { log "$*"; exit 1; }

pid_of() { [[ -s $DIR/run/$1.pid ]] && tr -dc '0-9' < "$DIR/run/$1.pid" || true; }

# alive NAME: the recorded pid exists and is that program (guards against a reused pid).
alive() {
  local pid comm
  pid=$(pid_of "$1")
  [[ -n $pid ]] && kill -0 "$pid" 2>/dev/null || return 1
  comm=$(cat "/proc/$pid/comm" 2>/dev/null || true)
  [[ $comm == "$1"* ]]
}

wait_for() {  # wait_for SECONDS DESCRIPTION COMMAND...
  local t=$1 what=$2; shift 2
  local end=$((SECONDS + t))
  until "$@" >/dev/null 2>&1; do
    ((SECONDS < end)) || die "timed out waiting for $what (logs: $DIR/log)"
    sleep 0.2
  done
}

install_packages() {
  local missing=() p
  for p in "${PKGS[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
  ((${#missing[@]} == 0)) && return 0
  [[ $(id -u) == 0 ]] || die "missing packages ${missing[*]}; install them as root (apt-get install ${missing[*]})"
  log "installing ${missing[*]}"
  # Keep package scripts from starting system-wide services (no systemd here; we run our own daemons).
  local policy=/usr/sbin/policy-rc.d created=0
  if [[ ! -e $policy ]]; then printf '#!/bin/sh\nexit 101\n' > "$policy"; chmod +x "$policy"; created=1; fi
  if ! DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >"/tmp/slurm_local_apt.log" 2>&1; then
    apt-get update -qq >/dev/null 2>&1 || true
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >"/tmp/slurm_local_apt.log" 2>&1 \
      || { ((created)) && rm -f "$policy"; die "apt-get install failed (see /tmp/slurm_local_apt.log)"; }
  fi
  ((created)) && rm -f "$policy"
  return 0
}

write_configs() {
  mkdir -p "$DIR"/{etc,run,log,state,spool,munge,mysql}
  chmod 700 "$DIR" "$DIR/munge"
  if [[ ! -s $DIR/munge/munge.key ]]; then
    dd if=/dev/urandom of="$DIR/munge/munge.key" bs=1024 count=1 status=none
    chmod 400 "$DIR/munge/munge.key"
  fi
  [[ -s $DIR/etc/dbpass ]] || { head -c 18 /dev/urandom | base64 | tr -dc 'A-Za-z0-9' > "$DIR/etc/dbpass"; chmod 600 "$DIR/etc/dbpass"; }
  local mem cpus gres_types="" node_gres=""
  cpus=$(nproc)
  mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)
  # Stand-in GPUs: the devices of GRES gpu (slurmd checks that each is a device; with TaskPlugin=task/none nothing
  # constrains access to them). SLURM sets a job's CUDA_VISIBLE_DEVICES from their indexes.
  rm -rf "$DIR/dev"
  : > "$DIR/etc/gres.conf"
  if ((GPUS > 0)); then
    mkdir -p "$DIR/dev"
    local i
    for ((i = 0; i < GPUS; i++)); do
      # a character device like /dev/null's (1:3): slurmd takes only devices (a plain file: "not a valid character
      # or block device", and the job's CUDA_VISIBLE_DEVICES stays empty); opening one reads nothing, as /dev/null
      mknod "$DIR/dev/nvidia$i" c 1 3 2>/dev/null || die "cannot make the stand-in device $DIR/dev/nvidia$i (mknod needs root)"
    done
    gres_types=$'GresTypes=gpu\nAccountingStorageTRES=gres/gpu'  # sacct's AllocTRES shows the GPUs too
    node_gres="Gres=gpu:$GPUS"
    printf 'AutoDetect=off\nNodeName=%s Name=gpu File=%s/dev/nvidia[0-%d]\n' "$HOST" "$DIR" $((GPUS - 1)) \
      > "$DIR/etc/gres.conf"
  fi
  cat > "$DIR/etc/slurm.conf" <<EOF
# Generated by scripts/slurm_local.sh: one node (this host) in one partition.
ClusterName=taco
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$DIR/munge/munge.socket
StateSaveLocation=$DIR/state
SlurmdSpoolDir=$DIR/spool
SlurmctldPidFile=$DIR/run/slurmctld.pid
SlurmdPidFile=$DIR/run/slurmd.pid
SlurmctldLogFile=$DIR/log/slurmctld.log
SlurmdLogFile=$DIR/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
SchedulerType=sched/backfill
JobRequeue=1
ReturnToService=2
MpiDefault=none
SwitchType=switch/none
KillWait=5
InactiveLimit=0
MinJobAge=600
MailProg=/bin/true
AccountingStorageType=accounting_storage/slurmdbd
AccountingStorageHost=127.0.0.1
AccountingStoragePort=$DBD_PORT
AccountingStoragePass=$DIR/munge/munge.socket
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
$gres_types
NodeName=$HOST NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem $node_gres State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  cat > "$DIR/etc/slurmdbd.conf" <<EOF
# Generated by scripts/slurm_local.sh: accounting in a private MariaDB on 127.0.0.1:$DB_PORT.
AuthType=auth/munge
AuthInfo=socket=$DIR/munge/munge.socket
DbdAddr=127.0.0.1
DbdHost=$HOST
DbdPort=$DBD_PORT
SlurmUser=root
PidFile=$DIR/run/slurmdbd.pid
LogFile=$DIR/log/slurmdbd.log
StorageType=accounting_storage/mysql
StorageHost=127.0.0.1
StoragePort=$DB_PORT
StorageUser=slurm
StoragePass=$(cat "$DIR/etc/dbpass")
StorageLoc=slurm_acct_db
EOF
  chmod 600 "$DIR/etc/slurmdbd.conf"
}

start_munged() {
  alive munged && return 0
  rm -f "$DIR/munge/munge.socket" "$DIR/munge/munge.socket.lock"
  munged --force --socket="$DIR/munge/munge.socket" --key-file="$DIR/munge/munge.key" \
    --pid-file="$DIR/run/munged.pid" --log-file="$DIR/log/munged.log" --seed-file="$DIR/munge/munged.seed"
  wait_for 10 munged test -S "$DIR/munge/munge.socket"
}

db() { mariadb --no-defaults -S "$DIR/mysql/mysqld.sock" -u root "$@"; }

start_mariadb() {
  if ! alive mariadbd; then
    if [[ ! -d $DIR/mysql/data/mysql ]]; then
      mariadb-install-db --no-defaults --user=root --datadir="$DIR/mysql/data" >"$DIR/log/mariadb-install.log" 2>&1 \
        || die "mariadb-install-db failed (see $DIR/log/mariadb-install.log)"
    fi
    rm -f "$DIR/mysql/mysqld.sock"
    nohup mariadbd --no-defaults --user=root --datadir="$DIR/mysql/data" --socket="$DIR/mysql/mysqld.sock" \
      --port="$DB_PORT" --bind-address=127.0.0.1 --skip-name-resolve --pid-file="$DIR/run/mariadbd.pid" \
      --log-error="$DIR/log/mariadb.log" --innodb-buffer-pool-size=64M >/dev/null 2>&1 &
    wait_for 30 mariadb db -e "SELECT 1"
  fi
  db -e "CREATE USER IF NOT EXISTS 'slurm'@'127.0.0.1' IDENTIFIED BY '$(cat "$DIR/etc/dbpass")';
         GRANT ALL ON slurm_acct_db.* TO 'slurm'@'127.0.0.1'; FLUSH PRIVILEGES;"
}

start_slurmdbd() {
  alive slurmdbd && return 0
  slurmdbd
  wait_for 30 slurmdbd sacctmgr -n show cluster
  sacctmgr -i -Q add cluster taco >/dev/null 2>&1 || true
}

start_slurmctld() {
  alive slurmctld && return 0
  slurmctld
  wait_for 30 slurmctld scontrol ping
}

start_slurmd() {
  alive slurmd && return 0
  slurmd -N "$HOST"
  wait_for 30 "node $HOST to register" node_ready
}

node_ready() {
  local state
  state=$(sinfo -h -n "$HOST" -o %T 2>/dev/null | head -1)
  case $state in
    idle|mixed|allocated) return 0 ;;
    down*|drain*|drained*) scontrol update NodeName="$HOST" State=RESUME >/dev/null 2>&1 || true; return 1 ;;
    *) return 1 ;;
  esac
}

all_alive() { local d; for d in "${DAEMONS[@]}"; do alive "$d" || return 1; done; }

conf_sum() { { cat "$DIR/etc/slurm.conf" "$DIR/etc/gres.conf"; find "$DIR/dev" -printf "%y %p\n"; } 2>/dev/null | md5sum || true; }

cmd_up() {
  install_packages
  local before
  before=$(conf_sum)
  write_configs
  if all_alive && scontrol ping >/dev/null 2>&1 && node_ready; then
    if [[ $(conf_sum) == "$before" ]]; then
      log "already up ($DIR)"
      cmd_env
      return 0
    fi
    log "settings changed: restarting slurmctld and slurmd"
    stop_daemons slurmd slurmctld
  fi
  start_munged
  start_mariadb
  start_slurmdbd
  start_slurmctld
  start_slurmd
  log "up: node $HOST idle, ${CTLD_PORT}-${DB_PORT}, logs in $DIR/log"
  cmd_env
}

stop_daemons() {  # stop_daemons NAME...: TERM each recorded pid at once, KILL those alive after 10 s
  local name pid i pids=()
  for name in "$@"; do
    if alive "$name"; then pid=$(pid_of "$name"); kill -TERM "$pid" 2>/dev/null || true; pids+=("$pid"); fi
  done
  for ((i = 0; i < 100; i++)); do
    local left=0
    for pid in "${pids[@]}"; do kill -0 "$pid" 2>/dev/null && left=1; done
    ((left)) || break
    sleep 0.1
  done
  for pid in "${pids[@]}"; do
    if kill -0 "$pid" 2>/dev/null; then log "pid $pid ignored TERM; killing"; kill -KILL "$pid" 2>/dev/null || true; fi
  done
  for name in "$@"; do rm -f "$DIR/run/$name.pid"; done
}

cmd_down() {
  if alive slurmctld; then
    local ids
    ids=$(squeue -h -o %A 2>/dev/null | sort -u | tr '\n' ' ')
    if [[ -n ${ids// } ]]; then
      log "cancelling jobs $ids"
      # shellcheck disable=SC2086
      scancel $ids 2>/dev/null || true
      local end=$((SECONDS + 30))
      while [[ -n $(squeue -h -o %A 2>/dev/null) ]] && ((SECONDS < end)); do sleep 0.5; done
    fi
  fi
  stop_daemons "${DAEMONS[@]}"
  if [[ ${1:-} == --purge ]]; then rm -rf "$DIR"; log "purged $DIR"; fi
  log "down"
}

cmd_status() {
  local d rc=0
  for d in "${DAEMONS[@]}"; do
    if alive "$d"; then echo "$d: running (pid $(pid_of "$d"))"; else echo "$d: stopped"; rc=1; fi
  done
  return $rc
}

cmd_env() { echo "export SLURM_CONF=$DIR/etc/slurm.conf"; }

case ${1:-} in
  up) cmd_up ;;
  down) shift; cmd_down "${1:-}" ;;
  env) cmd_env ;;
  status) cmd_status ;;
  *) echo "usage: $0 up | down [--purge] | env | status" >&2; exit 2 ;;
esac
