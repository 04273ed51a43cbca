#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for tests/slurm.rs: munge, slurmctld and slurmd
# on localhost, started by hand (no systemd). Installs Debian's packages when they are missing.
# Idempotent: a cluster already up is left as it is. Exits non-zero (with a message) when
# Slurm cannot be installed or started; CI then runs on and tests/slurm.rs skips, saying so.
set -uo pipefail

log() { echo "slurm setup: $*" >&2; }

if ! command -v sbatch >/dev/null 2>&1 || ! command -v slurmctld >/dev/null 2>&1 \
    || ! command -v slurmd >/dev/null 2>&1 || ! command -v munged >/dev/null 2>&1; then
    if ! command -v apt-get >/dev/null 2>&1; then
        log "no apt-get: cannot install Slurm"; exit 1
    fi
    log "installing slurm-wlm and munge from Debian's packages"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null) \
        || { log "apt-get could not install slurm-wlm and munge"; exit 1; }
fi

if sinfo -h -o '%t' 2>/dev/null | grep -qE '^(idle|mix|alloc)'; then
    log "a Slurm cluster is already up"; exit 0
fi

host=$(hostname -s)
cpus=$(nproc)
mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)

# munge: a key, then the daemon (as its own user when there is one).
mkdir -p /etc/munge /var/lib/munge /var/log/munge /run/munge
if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
if id munge >/dev/null 2>&1; then
    chown -R munge:munge /etc/munge /var/lib/munge /var/log/munge /run/munge
fi
chmod 0700 /etc/munge /var/lib/munge /var/log/munge
chmod 0400 /etc/munge/munge.key
chmod 0755 /run/munge
if ! pgrep -x munged >/dev/null; then
    if id munge >/dev/null 2>&1; then
        runuser -u munge -- /usr/sbin/munged || { log "munged did not start"; exit 1; }
    else
        /usr/sbin/munged --force || { log "munged did not start"; exit 1; }
    fi
fi

mkdir -p /etc/slurm /var/spool/slurmctld /var/spool/slurmd /var/log/slurm
cat > /etc/slurm/slurm.conf <<CONF
# Written by hushfuse's scripts/slurm/ci-setup.sh: one node, this machine.
ClusterName=hushfuse-ci
SlurmctldHost=${host}(127.0.0.1)
SlurmUser=root
SlurmdUser=root
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
SchedulerType=sched/backfill
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
MinJobAge=300
KillWait=5
Waittime=0
NodeName=${host} NodeAddr=127.0.0.1 CPUs=${cpus} RealMemory=${mem} State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
# slurmd reads cgroup.conf only with cgroup plugins; an empty one keeps older versions quiet.
[ -f /etc/slurm/cgroup.conf ] || echo "CgroupPlugin=autodetect" > /etc/slurm/cgroup.conf

pgrep -x slurmctld >/dev/null || /usr/sbin/slurmctld || { log "slurmctld did not start"; tail -20 /var/log/slurm/slurmctld.log >&2; exit 1; }
pgrep -x slurmd >/dev/null || /usr/sbin/slurmd || { log "slurmd did not start"; tail -20 /var/log/slurm/slurmd.log >&2; exit 1; }

for _ in $(seq 60); do
    state=$(sinfo -h -o '%t' 2>/dev/null | head -1)
    case "$state" in
        idle|mix|alloc) log "cluster up: node ${host}, ${cpus} CPUs (state ${state})"; exit 0 ;;
        down*|drain*) scontrol update NodeName="${host}" State=RESUME >/dev/null 2>&1 ;;
    esac
    sleep 1
done
log "the node did not come up (state: ${state:-none})"
tail -20 /var/log/slurm/slurmctld.log /var/log/slurm/slurmd.log >&2
exit 1
