#!/usr/bin/env bash
# Screenshot of the stock rerun viewer (0.36.3) showing a recording, the way a user sees it:
#
#   scripts/viewer-shot.sh FILE.rrd OUT.png [WIDTHxHEIGHT]     (default 1920x1080)
#
# Installs what it needs on first use: Xvfb, Mesa's Vulkan driver (lavapipe) and ImageMagick
# with apt-get, `rerun-sdk==0.36.3` with pip into a virtualenv kept under
# ${RATELAB_VIEWER_VENV:-~/.cache/ratelab/viewer-venv}. The viewer runs on a private Xvfb
# display with the Composite extension off (with it on, rerun's window is all black under
# Xvfb) and the Vulkan backend (the GL one cannot draw to R32Float). rerun saves the picture,
# then may exit non-zero ("Failed to take store hub"), so the script judges by the picture.
# The viewer's start-up notifications (a Docker notice, a Wgpu validation message) sometimes
# cover the top-right corner when the picture is taken: take it again if one hides something.
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
command -v Xvfb > /dev/null || need+=(xvfb)
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

# A private X display; Xvfb picks a free number and writes it to fd 3.
work="$(mktemp -d)"
xvfb_pid=""
cleanup() {
  [ -n "$xvfb_pid" ] && kill "$xvfb_pid" 2> /dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
Xvfb -displayfd 3 -screen 0 "${size}x24" -extension Composite -nolisten tcp \
  3> "$work/display" 2> "$work/xvfb.log" &
xvfb_pid=$!
for _ in $(seq 1 100); do
  [ -s "$work/display" ] && break
  sleep 0.1
done
if ! [ -s "$work/display" ]; then
  echo "Xvfb did not start:" >&2
  cat "$work/xvfb.log" >&2
  exit 1
fi
display=":$(head -n1 "$work/display")"

rm -f "$out"
mkdir -p "$(dirname "$out")"
set +e
DISPLAY="$display" WGPU_BACKEND=vulkan RERUN_ANALYTICS=0 \
  timeout 300 "$venv/bin/rerun" --window-size "$size" --screenshot-to "$out" "$file" \
  > "$work/rerun.log" 2>&1
status=$?
set -e
if [ -s "$out" ] && identify "$out" > /dev/null 2>&1; then
  echo "$out ($(identify -format '%wx%h' "$out"); rerun exited $status)"
else
  echo "no screenshot (rerun exited $status):" >&2
  tail -n 20 "$work/rerun.log" >&2
  exit 1
fi
