#!/usr/bin/env bash
# The Python package's tests (tests/py): build the wheel as `pip wheel .` does (maturin; its
# Rust build shares cargo's target directory, CARGO_TARGET_DIR when set), install it into a
# fresh virtual environment with pytest, and run them there. ./scripts/test.sh runs this
# after the Rust tests. Extra arguments go to pytest.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
pip_quiet=(--quiet --disable-pip-version-check)
echo "ratelab: building the wheel (pip wheel .) ..." >&2
started=$SECONDS
python3 -m pip wheel "${pip_quiet[@]}" --no-deps --wheel-dir "$work/dist" "$root"
echo "ratelab: wheel built in $((SECONDS - started)) s" >&2
started=$SECONDS
python3 -m venv "$work/venv"
"$work/venv/bin/python" -m pip install "${pip_quiet[@]}" "$work"/dist/ratelab-*.whl "pytest==9.2.0" "nbclient==0.11.0" "nbformat==5.11.1" "ipykernel==7.4.0" "matplotlib==3.11.2" "pandas==3.1.1" "rerun-sdk[notebook]==0.41.0"
echo "ratelab: installed into a fresh virtual environment in $((SECONDS - started)) s" >&2
cd "$work"
# Not `exec`: the trap removes the environment (1.3 GB) when pytest ends, as it fails too.
"$work/venv/bin/python" -m pytest -q -p no:cacheprovider "$@" "$root/tests/py"
