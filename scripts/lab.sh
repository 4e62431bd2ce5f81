#!/usr/bin/env bash
# Run the ratelab lab (or any subcommand: ./scripts/lab.sh run --smoke).
# Fetches MuJoCo 3.17.0 into .mujoco/ on first use; builds in release mode.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup-mujoco.sh"
# Python brains and nodes import NumPy: your own virtual environment if one is active, else
# .venv (made on first use with what the shipped examples need).
if [ -z "${VIRTUAL_ENV:-}" ]; then
  VIRTUAL_ENV="$("$root/scripts/setup-python.sh")"
  export VIRTUAL_ENV
fi
cd "$root"
exec cargo run --quiet --release --bin ratelab -- "$@"
