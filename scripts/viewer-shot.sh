#!/usr/bin/env bash
# Screenshot of the stock rerun viewer (0.36.3) showing a recording, the way a user sees it:
#
#   scripts/viewer-shot.sh FILE.rrd OUT.png [WIDTHxHEIGHT]     (default 1920x1080)
#
# Installs what it needs on first use: Mesa's Vulkan driver (lavapipe) and ImageMagick with
# apt-get, `rerun-sdk==0.36.3` with pip into a virtualenv kept under
# ${RATELAB_VIEWER_VENV:-~/.cache/ratelab/viewer-venv}. The viewer runs headless (`--headless`:
# the same viewer, drawn offscreen, no X display) on the Vulkan backend (the GL one cannot
# draw to R32Float), as a new viewer (`--new`: else, with a viewer already listening on port
# 9876, rerun hands the file to that one and takes no picture), and saves the picture itself
# (`--screenshot-to`, in its screenshot style, at twice WIDTHxHEIGHT as on a high-dpi screen).
#
# No notifications in the picture, by construction:
# - `--screenshot-to` resizes the window for its 2x picture at start-up, before the first
#   frame, from egui's placeholder screen of 10000x10000 points: 20000 points at 2 px each, a
#   40000x40000 surface, beyond any GPU's limit (lavapipe's is 16384), whatever the window or
#   screen size: the viewer's red "Wgpu validation error … Requested was (40000, 40000)".
#   Headless there is no window: the offscreen renderer ignores the resize, no error.
# - The viewer shows its own info and warning log lines (software rasterizer, "Listening for
#   gRPC connections", "Loading …") as notifications for 4 s, and `--screenshot-to` takes the
#   picture 10 frames after start, when they may still show. RUST_LOG=error keeps the viewer
#   from logging them. Errors still log, and would show: if the viewer logs one, the script
#   prints it and exits 1 (the picture is kept, to look at).
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
venv="${RATELAB_VIEWER_VENV:-$HOME/.cache/ratelab/viewer-venv}"
if ! "$venv/bin/rerun" --version 2> /dev/null | grep -q "0\.36\.3"; then
  python3 -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check rerun-sdk==0.36.3
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
set +e
env -u DISPLAY -u WAYLAND_DISPLAY WGPU_BACKEND=vulkan RERUN_ANALYTICS=0 RUST_LOG=error \
  timeout --kill-after=10 300 "$viewer" --headless --new --window-size "$size" \
  --screenshot-to "$out" "$file" > "$work/rerun.log" 2>&1
status=$?
set -e
if ! [ -s "$out" ] || ! identify "$out" > /dev/null 2>&1; then
  echo "no screenshot (rerun exited $status):" >&2
  tail -n 20 "$work/rerun.log" >&2
  exit 1
fi
if grep -aq "ERROR" "$work/rerun.log"; then
  echo "$out: the viewer logged errors, which the picture may show as notifications:" >&2
  grep -a -A4 "ERROR" "$work/rerun.log" | head -n 40 >&2
  exit 1
fi
echo "$out ($(identify -format '%wx%h' "$out"); rerun exited $status)"
