#!/usr/bin/env bash
# Binaries against each other and bare Zenoh on large messages (issue 76 item 1), in one
# sitting: /image's one-way p50 as each BINARY's launch of the camera graph reports it
# (benches/graphs/camera-beside.toml at SIZE MiB, `--processes --clock real`, 20 s at
# 30 Hz, the vision node half a period after the camera, as scripts/bench-image.py runs it),
# then bare Zenoh's (`examples/image_floor`, 600 frames). ROUNDS rounds of each size; prints
# one line per launch. scripts/bench-image.py is the whole benchmark (CPU, the one-process
# runs, dora-rs); this is its latency alone, for a before and after.
# Usage: scripts/bench-image-ab.sh ROUNDS SIZES BINARY [BINARY...]   (SIZES: e.g. 1,4)
# (build the floor first: cargo build --release --locked --example image_floor)
set -euo pipefail
rounds=${1:?rounds}; sizes=${2:?sizes}; shift 2
[ $# -ge 1 ] || { echo "usage: $0 ROUNDS SIZES BINARY [BINARY...]" >&2; exit 2; }
root=$(cd "$(dirname "$0")/.." && pwd)
target=${CARGO_TARGET_DIR:-$root/target}
floor=$(realpath "$target/release/examples/image_floor")
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
for m in ${sizes//,/ }; do
  side=$(python3 -c "print(int(round(1024 * $m ** 0.5)))")
  python3 - "$root/benches/graphs/camera-beside.toml" "$work/camera-$m.toml" "$side" <<'PY'
import sys
text = open(sys.argv[1]).read()
text = text.replace("width_px = 1024, height_px = 1024", f"width_px = {sys.argv[3]}, height_px = {sys.argv[3]}")
vision = 'name = "vision"\nkind = "image_estimator"\nrate_hz = 30\n'
assert vision in text, "camera-beside.toml's vision node changed"
open(sys.argv[2], "w").write(text.replace(vision, vision + "start_ms = 16.5\n"))
PY
done
for r in $(seq "$rounds"); do
  for m in ${sizes//,/ }; do
    for b in "$@"; do
      out=$(cd "$work" && "$b" launch "camera-$m.toml" --processes --clock real --duration 20 --headless 2>&1 || true)
      echo "round $r $m MiB $b: $(grep -o "wire /image into 'vision': [0-9]* samples, p50 [0-9.]* µs" <<<"$out" || echo "no /image line")"
    done
    echo "round $r $m MiB bare Zenoh: $("$floor" --count 600 --bytes $((m << 20)) | tail -1 | grep -o '"p50_us":[0-9.]*')"
  done
done
