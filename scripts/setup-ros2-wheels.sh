#!/usr/bin/env bash
# A ROS 2 user's Python environment, for the tests (tests/it/python_env.rs): a virtual
# environment of the `python3` ratelab embeds holding PyPI's ROS 2 Kilted wheels (rclpy,
# std_msgs, Fast DDS; about 250 MB), whose `.pth` bootstrapper re-executes the interpreter
# at start-up. ratelab must run a Python-node graph with it first on PATH and active. Makes
# .venv-ros2/ (git-ignored) once, pinned; idempotent, offline once done. Prints the
# environment's folder on stdout (the caller exports RATELAB_ROS2_VENV=<it>).
set -euo pipefail
RCLPY_VERSION=9.1.2
STD_MSGS_VERSION=5.5.1
RMW_FASTRTPS_VERSION=9.3.3
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv-ros2"
stamp="$venv/.ratelab-rclpy-$RCLPY_VERSION-std-msgs-$STD_MSGS_VERSION-rmw-fastrtps-$RMW_FASTRTPS_VERSION"
if [ ! -f "$stamp" ]; then
  echo "ratelab: making $venv with PyPI's ROS 2 wheels (ros-rclpy $RCLPY_VERSION, about 250 MB; a test's ROS 2 user environment) ..." >&2
  python3 -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    "ros-rclpy==$RCLPY_VERSION" "ros-std-msgs==$STD_MSGS_VERSION" \
    "ros-rmw-fastrtps-cpp==$RMW_FASTRTPS_VERSION" >&2
  touch "$stamp"
fi
echo "$venv"
