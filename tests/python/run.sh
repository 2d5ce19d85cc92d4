#!/usr/bin/env bash
# The Python package in a fresh virtual environment: `pip install ./python`
# (maturin builds the PyO3 extension; the Rust build reuses target/), then
# its pytest suite. Skips only if the package index is unreachable.
set -euo pipefail
cd "$(dirname "$0")/../.."
venv=target/python-venv
rm -rf "$venv"
python3 -m venv "$venv"
if ! "$venv/bin/pip" install -q --upgrade pip >/dev/null 2>&1; then
    echo "python: the package index is unreachable; skipping"
    exit 0
fi
started=$(date +%s)
CARGO_TARGET_DIR="$PWD/target" "$venv/bin/pip" install -q ./python
echo "python: pip install ./python took $(( $(date +%s) - started )) s"
"$venv/bin/pip" install -q pytest
# Outside python/, so that the installed package is the one imported.
(cd /tmp && "$OLDPWD/$venv/bin/python" -c "import capsule_mpc; print('python: import capsule_mpc ok,', capsule_mpc.Config.default())")
"$venv/bin/pytest" -q python/tests
