#!/usr/bin/env bash
# Run every test: unit, integration, end-to-end (the real binary in a pseudo-terminal).
# Fetches MuJoCo 3.17.0 into .mujoco/ on first use. Extra arguments go to `cargo test`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup-mujoco.sh"
cd "$root"
exec cargo test --release --locked "$@"
