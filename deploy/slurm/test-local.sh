#!/usr/bin/env bash
# The Slurm path, end to end, on this machine: installs Slurm and MUNGE from
# the Debian packages if missing, starts a one-node cluster (munged,
# slurmctld, slurmd; all state under a temporary directory, non-default
# ports), submits the sharded generation with submit.sh, waits for the merge,
# and compares the merged crate byte for byte with a single-process
# `capsule-mpc generate` of the same config. The cluster is shut down on exit,
# whatever happens (its processes are ended by their ids).
#
#   deploy/slurm/test-local.sh [SHARD_COUNT...]     (default: 3)
#
# Environment: CAPSULE_SLURM_CONFIG (default tests/configs/shard-m2.toml),
# CAPSULE_SLURM_CPUS_PER_TASK (default 1), CAPSULE_SLURM_PORT (slurmctld's
# port, default 16817; slurmd uses the next one), CAPSULE_SLURM_TIMEOUT_S
# (per submission, default 900). Needs root or passwordless sudo (the
# daemons run as root); prints SKIP and exits 0 only when Slurm is missing
# and cannot be installed.
set -euo pipefail
cd "$(dirname "$0")/../.."
repo=$PWD
config=$repo/${CAPSULE_SLURM_CONFIG:-tests/configs/shard-m2.toml}
cpus_per_task=${CAPSULE_SLURM_CPUS_PER_TASK:-1}
port=${CAPSULE_SLURM_PORT:-16817}
timeout_s=${CAPSULE_SLURM_TIMEOUT_S:-900}
counts=("$@")
[ ${#counts[@]} -gt 0 ] || counts=(3)

if [ "$(id -u)" -eq 0 ]; then
    SUDO=()
elif command -v sudo >/dev/null && sudo -n true 2>/dev/null; then
    SUDO=(sudo -n)
else
    SUDO=none
fi

need_install=no
for tool in munged mungekey slurmctld slurmd sbatch squeue scontrol sinfo; do
    command -v "$tool" >/dev/null || need_install=yes
done
if [ $need_install = yes ]; then
    if [ "${SUDO[*]}" = none ]; then
        echo "SKIP: Slurm is not installed and this user is neither root nor has passwordless sudo to install it"
        exit 0
    fi
    echo "== installing slurm-wlm and munge from the Debian packages"
    if ! { "${SUDO[@]}" apt-get update -qq &&
        DEBIAN_FRONTEND=noninteractive "${SUDO[@]}" apt-get install -y -qq --no-install-recommends \
            slurm-wlm munge >/dev/null; }; then
        echo "SKIP: apt-get could not install slurm-wlm and munge (no package index or network?)"
        exit 0
    fi
fi
if [ "${SUDO[*]}" = none ]; then
    echo "SKIP: the one-node cluster runs its daemons as root; this user is neither root nor has passwordless sudo"
    exit 0
fi
if [ ${#SUDO[@]} -gt 0 ]; then
    # Re-run the whole script as root (the daemons, the jobs and the
    # cleanup then share one user).
    exec "${SUDO[@]}" env "PATH=$PATH" CAPSULE_SLURM_CONFIG="${CAPSULE_SLURM_CONFIG:-}" \
        CAPSULE_SLURM_CPUS_PER_TASK="$cpus_per_task" CAPSULE_SLURM_PORT="$port" \
        CAPSULE_SLURM_TIMEOUT_S="$timeout_s" "$0" "${counts[@]}"
fi

echo "== building capsule-mpc"
cargo build --release --quiet --bin capsule-mpc
bin=$repo/target/release/capsule-mpc

run=$(mktemp -d /tmp/capsule-slurm.XXXXXX)
pids=()
cleanup() {
    status=$?
    trap - EXIT INT TERM
    set +e
    if [ -n "${SLURM_CONF:-}" ] && [ -f "$SLURM_CONF" ]; then
        scancel --quiet -u "$(id -un)" >/dev/null 2>&1
    fi
    for ((k = ${#pids[@]} - 1; k >= 0; k--)); do
        kill "${pids[k]}" 2>/dev/null
    done
    for pid in "${pids[@]}"; do
        for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
        kill -9 "$pid" 2>/dev/null
    done
    if [ $status -ne 0 ]; then
        echo "== test-local.sh failed; daemon and job logs:"
        tail -n 20 "$run"/*.log "$run"/work-*/logs/*.out 2>/dev/null
    fi
    rm -rf "$run"
    echo "== one-node cluster shut down"
    exit $status
}
trap cleanup EXIT INT TERM

# Seconds since a `date +%s%N` stamp, one decimal (no bc on a fresh machine).
since() {
    local ms=$((($(date +%s%N) - $1) / 1000000))
    printf '%d.%d' $((ms / 1000)) $((ms % 1000 / 100))
}

host=$(hostname -s)
cpus=$(nproc)
mkdir -p "$run/state" "$run/spool"

echo "== starting munged"
mungekey --create --keyfile="$run/munge.key" 2>/dev/null ||
    { dd if=/dev/urandom of="$run/munge.key" bs=1024 count=1 status=none; }
chmod 0600 "$run/munge.key"
munged --foreground --force --socket="$run/munge.socket" --key-file="$run/munge.key" \
    --pid-file="$run/munged.pid" --log-file="$run/munged.log" --seed-file="$run/munged.seed" \
    >>"$run/munged.log" 2>&1 &
pids+=($!)
for _ in $(seq 100); do [ -S "$run/munge.socket" ] && break; sleep 0.1; done
[ -S "$run/munge.socket" ] || { echo "munged did not start"; exit 1; }

cat >"$run/slurm.conf" <<CONF
ClusterName=capsule-local
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$port
SlurmdPort=$((port + 1))
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$run/munge.socket
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MinJobAge=600
StateSaveLocation=$run/state
SlurmdSpoolDir=$run/spool
SlurmctldPidFile=$run/slurmctld.pid
SlurmdPidFile=$run/slurmd.pid
SlurmctldLogFile=$run/slurmctld.log
SlurmdLogFile=$run/slurmd.log
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
export SLURM_CONF=$run/slurm.conf

echo "== starting slurmctld and slurmd ($host, $cpus CPUs, port $port)"
slurmctld -D -i -f "$SLURM_CONF" >>"$run/slurmctld.log" 2>&1 &
pids+=($!)
slurmd -D -f "$SLURM_CONF" >>"$run/slurmd.log" 2>&1 &
pids+=($!)
for _ in $(seq 300); do
    state=$(sinfo -h -n "$host" -o %T 2>/dev/null || true)
    [ "$state" = idle ] && break
    sleep 0.2
done
[ "$state" = idle ] || { echo "the node did not become idle (state '$state')"; exit 1; }
sinfo

echo "== single-process generation of $(basename "$config")"
t0=$(date +%s%N)
RAYON_NUM_THREADS=$cpus "$bin" generate --config "$config" --out "$run/single" 2>/dev/null | tail -n 1
echo "single process ($cpus threads): $(since "$t0") s"

for n in "${counts[@]}"; do
    echo "== Slurm: $n shard(s), $cpus_per_task CPU(s) per task"
    work=$run/work-$n
    t0=$(date +%s%N)
    merge=$(CAPSULE_BIN=$bin deploy/slurm/submit.sh "$config" "$work" "$run/merged-$n" "$n" \
        --cpus-per-task="$cpus_per_task")
    deadline=$(($(date +%s) + timeout_s))
    while :; do
        state=$(scontrol show job "$merge" 2>/dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p')
        case $state in
            COMPLETED) break ;;
            FAILED | CANCELLED | TIMEOUT | NODE_FAIL | OUT_OF_MEMORY | BOOT_FAIL | DEADLINE | PREEMPTED)
                echo "merge job $merge ended $state"
                exit 1 ;;
        esac
        if squeue -h -o '%j %r' | grep -q DependencyNeverSatisfied; then
            echo "a shard failed: its dependents can never run"
            squeue
            exit 1
        fi
        if [ "$(date +%s)" -gt $deadline ]; then
            echo "timed out after ${timeout_s} s waiting for merge job $merge (state '$state')"
            squeue
            exit 1
        fi
        sleep 0.5
    done
    echo "slurm, $n shard(s) x $cpus_per_task CPU(s): submit to merged in $(since "$t0") s"
    tail -n 1 "$work/logs/merge.out"
    if ! diff -r "$run/single" "$run/merged-$n"; then
        echo "FAIL: the merged crate of $n shards differs from the single-process one"
        exit 1
    fi
    cmp "$run/single/controller.tables.bin" "$run/merged-$n/controller.tables.bin"
    # Per round: units computed and the slowest shard's time (from the logs).
    cat "$work"/logs/round-*-shard-*.out | awk '
        /^round [0-9]+, shard/ {
            r = $2 + 0; u[r] += $5; if (r > last) last = r
            t = $0; sub(/.* units in /, "", t); t += 0
            w = $0; sub(/.*slowest /, "", w); w += 0
            if (t > m[r]) m[r] = t; s[r] += t; if (w > x[r]) x[r] = w
        }
        END {
            for (r = 0; r <= last; r++) {
                printf "  round %d: %5d units, slowest shard %6.1f s, all shards %6.1f s, slowest unit %5.2f s\n", r, u[r], m[r], s[r], x[r]
                tm += m[r]; ts += s[r]
            }
            printf "  rounds: slowest shards sum to %.1f s, all shards %.1f s\n", tm, ts
        }'
    echo "ok: $n shard(s) merged byte-identical to the single-process run ($(stat -c %s "$run/merged-$n/controller.tables.bin") bytes of tables)"
done
