#!/usr/bin/env bash
# Round trip of the Pulseq export: .seq files written by the project's Rust
# writer are read back by pypulseq (tests/pulseq/check_seq.py), which runs its
# timing check and compares the x gradient with the run's u(t).
#
# Creates (once) a Python virtual environment with pinned pypulseq under the
# cargo target directory. Skips, printing why, only when the Python package
# index cannot be reached to install it; any other failure fails.
#
# Runs: two hand-made runs (the capsule-mpc-pulseq example synthetic_run) and
# two simulated ones (`capsule-mpc simulate --scenario C --sampling
# variable|constant --json ... --pulseq ...`).
#
# Usage: tests/pulseq/run.sh [--figure]
#   --figure  also redraw docs/figures/pulseq.png (from the variable-sampling run)
set -euo pipefail
cd "$(dirname "$0")/../.."

TARGET=${CARGO_TARGET_DIR:-target}
VENV="$TARGET/pulseq-venv"
OUT="$TARGET/pulseq-check"
PYTHON=${PYTHON:-python3}
REQUIREMENTS=(pypulseq==1.5.0.post1 numpy==2.4.6 scipy==1.17.1 matplotlib==3.11.2)

figure=0
for arg in "$@"; do
    case "$arg" in
        --figure) figure=1 ;;
        *) echo "usage: $0 [--figure]" >&2; exit 2 ;;
    esac
done

if [ "$(cat "$VENV/.requirements" 2>/dev/null)" != "${REQUIREMENTS[*]}" ]; then
    echo "== pulseq: creating $VENV with ${REQUIREMENTS[*]}"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
    probe=$(mktemp -d)
    if ! "$VENV/bin/pip" download --quiet --no-deps --disable-pip-version-check \
        --timeout 30 --retries 2 -d "$probe" "${REQUIREMENTS[0]}" 2>"$probe/stderr"; then
        if grep -qiE 'NewConnectionError|ConnectTimeout|ReadTimeout|connection broken|Max retries exceeded|Temporary failure in name resolution|Name or service not known|Network is unreachable|ProxyError|SSLError' "$probe/stderr"; then
            echo "SKIP pulseq round trip: the Python package index cannot be reached to install ${REQUIREMENTS[0]}:"
            grep -m 1 -iE 'NewConnectionError|ConnectTimeout|ReadTimeout|connection broken|Max retries exceeded|name resolution|not known|unreachable|ProxyError|SSLError' "$probe/stderr" | cut -c 1-300 | sed 's/^/    /'
            rm -rf "$probe" "$VENV"
            exit 0
        fi
        cat "$probe/stderr" >&2
        rm -rf "$probe"
        echo "pulseq: cannot download ${REQUIREMENTS[0]} (the index answered)" >&2
        exit 1
    fi
    rm -rf "$probe"
    "$VENV/bin/pip" install --quiet --disable-pip-version-check "${REQUIREMENTS[@]}"
    echo "${REQUIREMENTS[*]}" >"$VENV/.requirements"
fi

mkdir -p "$OUT"
echo "== pulseq: hand-made runs (capsule-mpc-pulseq example synthetic_run)"
cargo run --release --quiet -p capsule-mpc-pulseq --example synthetic_run -- "$OUT"

echo "== pulseq: simulated runs (capsule-mpc simulate --scenario C --pulseq)"
for sampling in variable constant; do
    cargo run --release --quiet -- simulate --scenario C --sampling "$sampling" \
        --json "$OUT/run-C-$sampling.json" --pulseq "$OUT/run-C-$sampling.seq"
done

# The first pair is the one --figure draws (docs/figures/pulseq.png).
pairs=(
    "$OUT/run-C-variable.seq" "$OUT/run-C-variable.json"
    "$OUT/run-C-constant.seq" "$OUT/run-C-constant.json"
    "$OUT/synthetic-ideal.seq" "$OUT/synthetic-ideal.json"
    "$OUT/synthetic-constant.seq" "$OUT/synthetic-constant.json"
)
plot=()
if [ "$figure" = 1 ]; then
    plot=(--plot docs/figures/pulseq.png)
fi

echo "== pulseq: pypulseq reads the files back"
"$VENV/bin/python" tests/pulseq/check_seq.py "${pairs[@]}" "${plot[@]}"
