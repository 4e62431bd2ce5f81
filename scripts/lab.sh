#!/usr/bin/env bash
# Run the ratelab lab (or any subcommand: ./scripts/lab.sh run --smoke).
# Fetches MuJoCo 3.17.0 into .mujoco/ on first use; builds in release mode.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup-mujoco.sh"
cd "$root"
exec cargo run --quiet --release --bin ratelab -- "$@"
