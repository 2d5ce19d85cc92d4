#!/bin/sh
# Entry point of one shard pod (copied into the image as capsule-shard):
# shard JOB_COMPLETION_INDEX of SHARDS of round ROUND, from the parts of the
# earlier rounds under WORK (a volume every pod of the job mounts).
#   env: ROUND, SHARDS, WORK (default /work), CONFIG (default /config/config.toml),
#        JOB_COMPLETION_INDEX (set by Kubernetes for Indexed Jobs)
set -eu
: "${ROUND:?}" "${SHARDS:?}" "${JOB_COMPLETION_INDEX:?not an Indexed Job pod}"
WORK=${WORK:-/work}
CONFIG=${CONFIG:-/config/config.toml}
i=$JOB_COMPLETION_INDEX
out="$WORK/round-$ROUND/shard-$i.part"
mkdir -p "$WORK/round-$ROUND"
# A retried pod whose part was already written (atomically) is done.
if [ -f "$out" ]; then
    echo "round $ROUND, shard $i/$SHARDS: $out exists"
    exit 0
fi
set --
r=0
while [ "$r" -lt "$ROUND" ]; do
    for p in "$WORK/round-$r"/*.part; do set -- "$@" "$p"; done
    r=$((r + 1))
done
exec capsule-mpc generate --config "$CONFIG" --shard "$i/$SHARDS" --round "$ROUND" \
    --out "$out" "$@"
