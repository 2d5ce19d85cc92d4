#!/usr/bin/env bash
# Sharded table generation on Kubernetes: one Indexed Job per round (each
# waits for the previous to complete; Kubernetes has no job dependencies),
# then the merge Job. Needs kubectl pointed at the cluster, the image pushed
# where the cluster can pull it, and a ReadWriteMany storage class.
#
#   deploy/k8s/run.sh CONFIG IMAGE SHARDS [CPUS_PER_SHARD] [PARALLELISM]
#
# e.g. deploy/k8s/run.sh configs/paper.toml registry.example.org/capsule-mpc:1 100 32
# The merged crate ends up in /work/generated on the capsule-work volume;
# CAPSULE_MODULE=three-capsules emits the three-capsule module instead.
set -euo pipefail
if [ $# -lt 3 ]; then
    sed -n '2,10p' "$0" >&2
    exit 2
fi
here=$(cd "$(dirname "$0")" && pwd)
config=$1 image=$2 shards=$3 cpus=${4:-1} parallelism=${5:-$3}
module=${CAPSULE_MODULE:-controller}
timeout_s=${CAPSULE_K8S_ROUND_TIMEOUT_S:-86400}
# Waits until job $1 is Complete; fails as soon as it is Failed (an index
# out of retries), or after timeout_s.
wait_job() {
    local deadline=$(($(date +%s) + timeout_s)) state
    while :; do
        state=$(kubectl get job "$1" -o jsonpath='{.status.conditions[?(@.status=="True")].type}')
        case " $state " in
            *" Complete "*) return 0 ;;
            *" Failed "*)
                echo "job $1 failed:" >&2
                kubectl describe job "$1" | tail -n 20 >&2
                return 1 ;;
        esac
        if [ "$(date +%s)" -gt "$deadline" ]; then
            echo "job $1: timed out after ${timeout_s} s" >&2
            return 1
        fi
        sleep 5
    done
}
kubectl apply -f "$here/volume.yaml"
kubectl create configmap capsule-config --from-file=config.toml="$config" \
    --dry-run=client -o yaml | kubectl apply -f -
# The round count (the config and the generator version decide it): from a
# local build if there is one, else from the image.
bin=${CAPSULE_BIN:-$here/../../target/release/capsule-mpc}
if [ -x "$bin" ]; then
    rounds=$("$bin" generate --config "$config" --rounds 2>/dev/null)
else
    rounds=$(docker run --rm -v "$(cd "$(dirname "$config")" && pwd):/c:ro" "$image" \
        generate --config "/c/$(basename "$config")" --rounds 2>/dev/null)
fi
echo "$rounds rounds of $shards shards"
render() {
    sed -e "s|__ROUND__|$1|g" -e "s|__SHARDS__|$shards|g" -e "s|__PARALLELISM__|$parallelism|g" \
        -e "s|__CPUS__|$cpus|g" -e "s|__IMAGE__|$image|g" -e "s|__MODULE__|$module|g" "$2"
}
for ((r = 0; r < rounds; r++)); do
    kubectl delete job "capsule-round-$r" --ignore-not-found
    render "$r" "$here/shard-job.yaml" | kubectl apply -f -
    wait_job "capsule-round-$r"
done
kubectl delete job capsule-merge --ignore-not-found
render 0 "$here/merge-job.yaml" | kubectl apply -f -
wait_job capsule-merge
kubectl logs job/capsule-merge
