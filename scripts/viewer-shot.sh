#!/usr/bin/env bash
# Screenshot of the stock rerun viewer (0.41.0, what `pip install rerun-sdk` gives a user)
# showing a recording, the way a user sees it:
#
#   scripts/viewer-shot.sh FILE.rrd OUT.png [WIDTHxHEIGHT]     (default 1920x1080)
#
# Installs what it needs on first use: Mesa's Vulkan driver (lavapipe) and ImageMagick with
# apt-get, `rerun-sdk==0.41.0` with pip into a virtualenv kept under
# ${RATELAB_VIEWER_VENV:-~/.cache/ratelab/viewer-venv-0.41}. The viewer runs headless
# (`--headless`: the same viewer, drawn offscreen, no X display) on the Vulkan backend (the GL
# one cannot draw to R32Float), on a port of its own, and the picture is taken through its
# control API (`scripts/viewer_shot.py`) once the recording has loaded: the viewer's own
# `--screenshot-to` shoots a few frames after start, before the data of ratelab's files has
# arrived (empty views in most takes). The picture is WIDTHxHEIGHT pixels.
#
# No notifications in the picture, by construction:
# - Headless there is no window, so no window-size limit of the GPU to run into.
# - The viewer shows its own info and warning log lines (software rasterizer, "Listening for
#   gRPC connections", "Loading …") as notifications for 4 s. RUST_LOG=error keeps the viewer
#   from logging them. Errors still log, and would show: if the viewer logs one, the script
#   prints it and exits 1 (the picture is kept, to look at). "XDG_RUNTIME_DIR is invalid" is
#   not the viewer's (a display library's, at start-up, headless) and is set aside.
set -euo pipefail

if [ $# -lt 2 ] || [ $# -gt 3 ]; then
  echo "usage: $0 FILE.rrd OUT.png [WIDTHxHEIGHT]" >&2
  exit 2
fi
file="$(realpath "$1")"
out="$(realpath -m "$2")"
size="${3:-1920x1080}"
if ! [[ "$size" =~ ^[0-9]+x[0-9]+$ ]]; then
  echo "size must look like 1920x1080, got '$size'" >&2
  exit 2
fi
[ -f "$file" ] || { echo "no such recording: $file" >&2; exit 2; }

# System packages (Debian/Ubuntu), only when missing.
need=()
command -v identify > /dev/null || need+=(imagemagick)
ls /usr/share/vulkan/icd.d/lvp_icd*.json > /dev/null 2>&1 || need+=(mesa-vulkan-drivers)
if [ ${#need[@]} -gt 0 ]; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${need[@]}" > /dev/null
fi

# The viewer of the matching version.
venv="${RATELAB_VIEWER_VENV:-$HOME/.cache/ratelab/viewer-venv-0.41}"
if ! "$venv/bin/rerun" --version 2> /dev/null | grep -q "rerun-cli 0\.41\.0"; then
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check rerun-sdk==0.41.0
  "$venv/bin/rerun" analytics disable > /dev/null 2>&1 || true
fi
# The viewer's own binary, not the `rerun` Python shim that runs it as a child (a timeout
# would stop the shim and leave the viewer running).
viewer="$("$venv/bin/python" -c 'import os, rerun_cli; print(os.path.join(os.path.dirname(rerun_cli.__file__), "rerun"))')"
[ -x "$viewer" ] || { echo "no rerun viewer binary at $viewer" >&2; exit 1; }

work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

rm -f "$out"
mkdir -p "$(dirname "$out")"
# A free port for this viewer alone (another may listen on rerun's 9876).
port="$("$venv/bin/python" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
env -u DISPLAY -u WAYLAND_DISPLAY WGPU_BACKEND=vulkan RERUN_ANALYTICS=0 RUST_LOG=error \
  timeout --kill-after=10 300 "$viewer" --headless --port "$port" --window-size "$size" \
  > "$work/rerun.log" 2>&1 &
viewer_pid=$!
trap 'kill "$viewer_pid" 2> /dev/null || true; rm -rf "$work"' EXIT
set +e
"$venv/bin/python" "$(dirname "${BASH_SOURCE[0]}")/viewer_shot.py" \
  "rerun+http://127.0.0.1:$port/proxy" "$file" "$out" 2> "$work/shot.err"
status=$?
set -e
kill "$viewer_pid" 2> /dev/null || true
wait "$viewer_pid" 2> /dev/null || true
if [ "$status" -ne 0 ]; then
  echo "no picture of $file:" >&2
  cat "$work/shot.err" >&2
  tail -n 20 "$work/rerun.log" >&2
  exit 1
fi
if ! [ -s "$out" ] || ! identify "$out" > /dev/null 2>&1; then
  echo "no screenshot:" >&2
  tail -n 20 "$work/rerun.log" >&2
  exit 1
fi
if grep -av "XDG_RUNTIME_DIR" "$work/rerun.log" | grep -aqi "error"; then
  echo "$out: the viewer logged errors, which the picture may show as notifications:" >&2
  grep -av "XDG_RUNTIME_DIR" "$work/rerun.log" | grep -ai -A4 "error" | head -n 40 >&2
  exit 1
fi
echo "$out ($(identify -format '%wx%h' "$out"))"
