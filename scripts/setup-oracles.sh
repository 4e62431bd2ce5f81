#!/usr/bin/env bash
# Independent implementations the tests check ratelab against, never used by ratelab itself:
# Zenoh's official Python API (PyPI eclipse-zenoh) and rosbags (CDR, RIHS01 type hashes,
# rosbag2), for the ROS 2 tests (tests/ros2/standin.py); ros2-pyterfaces (its pure-Python
# core: a second RIHS01 oracle); Foxglove's mcap and mcap-ros2-support (a bag's MCAP
# channels and their metadata, messages decoded from the schema the bag carries:
# tests/it/ros2_rosout.rs). Makes .venv-oracles/ (git-ignored)
# once, pinned; idempotent, offline once done. Prints its python on stdout.
set -euo pipefail
ZENOH_VERSION=1.10.2
ROSBAGS_VERSION=0.11.9
PYTERFACES_VERSION=0.3.0
MCAP_VERSION=1.6.0
MCAP_ROS2_VERSION=0.6.0
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$root/.venv-oracles"
stamp="$venv/.ratelab-zenoh-$ZENOH_VERSION-rosbags-$ROSBAGS_VERSION-pyterfaces-$PYTERFACES_VERSION-mcap-$MCAP_VERSION-$MCAP_ROS2_VERSION"
if [ ! -f "$stamp" ]; then
  echo "ratelab: making $venv with eclipse-zenoh $ZENOH_VERSION, rosbags $ROSBAGS_VERSION, ros2-pyterfaces $PYTERFACES_VERSION, mcap $MCAP_VERSION and mcap-ros2-support $MCAP_ROS2_VERSION (test oracles) ..." >&2
  python3 -m venv "$venv" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
    "eclipse-zenoh==$ZENOH_VERSION" "rosbags==$ROSBAGS_VERSION" \
    "ros2-pyterfaces==$PYTERFACES_VERSION" "mcap==$MCAP_VERSION" \
    "mcap-ros2-support==$MCAP_ROS2_VERSION" >&2
  touch "$stamp"
fi
echo "$venv/bin/python"
