#!/usr/bin/env bash
# Bounded fuzz run of every cargo-fuzz target (issue 8); see fuzz/README.md.
#
#   fuzz/run.sh [SECONDS_PER_TARGET] [TARGET...]     # default: 60 s each, all targets
#
# Installs cargo-fuzz if missing, builds the targets (release, debug
# assertions, AddressSanitizer), then runs each for SECONDS_PER_TARGET on
# one core, starting from fuzz/seeds/<target> (new inputs go to the
# untracked fuzz/corpus/<target>). Exits non-zero if any target crashed;
# the crashing input is in fuzz/artifacts/<target>/.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds="${1:-60}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(config capi runtime)
fi

if ! cargo fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --locked --version 0.13.2
fi

# cargo-fuzz passes nightly-only flags (-Zsanitizer, sanitizer coverage);
# the stable toolchain accepts them with RUSTC_BOOTSTRAP=1. One build job:
# the machine has two cores.
export RUSTC_BOOTSTRAP=1
export CARGO_BUILD_JOBS="${CARGO_BUILD_JOBS:-1}"

cargo fuzz build -O

failed=()
for t in "${targets[@]}"; do
    mkdir -p "fuzz/corpus/$t" fuzz/target
    log="fuzz/target/run-$t.log"
    echo "== fuzz target $t: ${seconds} s (log: $log)"
    set +e
    cargo fuzz run -O "$t" "fuzz/corpus/$t" "fuzz/seeds/$t" -- \
        -max_total_time="$seconds" -timeout=10 -rss_limit_mb=4096 \
        -print_final_stats=1 >"$log" 2>&1
    rc=$?
    set -e
    grep -E 'stat::number_of_executed_units|stat::peak_rss_mb|^Done [0-9]+ runs' "$log" || true
    if [ "$rc" -ne 0 ]; then
        failed+=("$t")
        grep -E -A3 'panicked|ERROR|SUMMARY|Test unit written' "$log" | head -40 >&2 || true
    fi
done

if [ ${#failed[@]} -ne 0 ]; then
    echo "fuzz: crash in ${failed[*]}: keep the input in fuzz/regressions/<target>/ and fix (see fuzz/README.md)" >&2
    exit 1
fi
echo "fuzz: ${targets[*]}: no crash in ${seconds} s each"
