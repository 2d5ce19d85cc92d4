#!/usr/bin/env bash
# Submits sharded table generation to Slurm: one array job of N shards per
# round, each depending on the previous round (afterok), and a merge job
# after the last round. Prints the merge job's id on stdout.
#
#   deploy/slurm/submit.sh CONFIG WORK_DIR OUT_DIR SHARDS [sbatch options...]
#
# WORK_DIR and OUT_DIR must be on a filesystem every node sees, and so must
# the binary (CAPSULE_BIN, default target/release/capsule-mpc). The merge
# emits the module CAPSULE_MODULE (default controller; three-capsules for
# the three-capsule preset) into OUT_DIR. Extra
# options go to every sbatch (e.g. --partition=compute --cpus-per-task=32
# --time=2:00:00). A failed shard cancels everything after it
# (--kill-on-invalid-dep=yes).
set -euo pipefail
if [ $# -lt 4 ]; then
    sed -n '2,12p' "$0" >&2
    exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
abs() { case $1 in /*) echo "$1" ;; *) echo "$PWD/$1" ;; esac; }
config=$(abs "$1")
work=$(abs "$2")
out=$(abs "$3")
shards=$4
shift 4
bin=$(abs "${CAPSULE_BIN:-target/release/capsule-mpc}")
[ -x "$bin" ] || { echo "submit.sh: no executable capsule-mpc at $bin (set CAPSULE_BIN)" >&2; exit 1; }
[ -f "$config" ] || { echo "submit.sh: no config file $config" >&2; exit 1; }
case $shards in
    '' | *[!0-9]* | 0) echo "submit.sh: SHARDS must be a positive integer, not '$shards'" >&2; exit 2 ;;
esac
if compgen -G "$work/round-*" >/dev/null; then
    echo "submit.sh: $work already holds round-* directories of an earlier run; use an empty work directory" >&2
    exit 1
fi
rounds=$("$bin" generate --config "$config" --rounds 2>/dev/null)
mkdir -p "$work/logs"
for ((r = 0; r < rounds; r++)); do mkdir -p "$work/round-$r"; done
common=(--parsable --kill-on-invalid-dep=yes "$@")
export CAPSULE_MODULE=${CAPSULE_MODULE:-controller}
export CAPSULE_BIN=$bin CAPSULE_CONFIG=$config CAPSULE_WORK=$work CAPSULE_OUT=$out CAPSULE_SHARDS=$shards
dep=()
for ((r = 0; r < rounds; r++)); do
    job=$(CAPSULE_ROUND=$r sbatch "${common[@]}" "${dep[@]}" --export=ALL \
        --array="0-$((shards - 1))" --job-name="capsule-r$r" \
        --output="$work/logs/round-$r-shard-%a.out" "$here/shard.sbatch")
    job=${job%%;*}
    echo "round $r: array job $job ($shards shards)" >&2
    dep=(--dependency="afterok:$job")
done
merge=$(sbatch "${common[@]}" "${dep[@]}" --export=ALL --job-name=capsule-merge \
    --output="$work/logs/merge.out" "$here/merge.sbatch")
merge=${merge%%;*}
echo "merge: job $merge -> $out" >&2
echo "$merge"
