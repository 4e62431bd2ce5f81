#!/usr/bin/env bash
# Run every test: unit, integration, end-to-end (the real binary in a pseudo-terminal), then
# the Python package's (scripts/test-python.sh: the wheel in a fresh virtual environment).
# Fetches MuJoCo 3.17.0 into .mujoco/ on first use. Extra arguments go to `cargo test`, and
# then only the Rust tests run.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup-mujoco.sh"
# The tests run Python brains and nodes with the packages of .venv (NumPy): ratelab adds an
# active virtual environment's packages at run time (the build does not depend on it).
VIRTUAL_ENV="$("$root/scripts/setup-python.sh")"
export VIRTUAL_ENV
# The ROS 2 tests' independent oracles (eclipse-zenoh, rosbags), in their own environment.
RATELAB_ORACLE_PYTHON="$("$root/scripts/setup-oracles.sh")"
export RATELAB_ORACLE_PYTHON
# A ROS 2 user's environment (PyPI's ROS 2 wheels), which must not break ratelab's Python.
RATELAB_ROS2_VENV="$("$root/scripts/setup-ros2-wheels.sh")"
export RATELAB_ROS2_VENV
cd "$root"
cargo test --release --locked "$@"
if [ $# -eq 0 ]; then
  # The launches of 128 and 256 processes, one at a time after the suite (ignored in it:
  # each takes the machine's cores and several GiB while it runs).
  cargo test --release --locked -p ratelab-lab --test it -- --ignored --exact --test-threads 1 \
    distributed::a_launch_of_128_processes_equals_the_in_process_run \
    distributed::a_launch_of_256_processes_equals_the_in_process_run
  "$root/scripts/test-python.sh"
fi
