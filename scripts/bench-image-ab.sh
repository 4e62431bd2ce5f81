#!/usr/bin/env bash
# Binaries against each other and bare Zenoh on large messages (issue 76 item 1), in one
# sitting: /image's one-way p50 as each BINARY's launch of the camera graph reports it
# (benches/graphs/camera-beside.toml at SIZE MiB, `--processes --clock real`, 20 s at
# 30 Hz, the vision node half a period after the camera: the graphs
# scripts/bench-image.py runs, which it writes), then bare Zenoh's (`examples/image_floor`,
# 600 frames). ROUNDS rounds of each size; prints one line per launch.
# scripts/bench-image.py is the whole benchmark (CPU, the one-process runs, dora-rs); this
# is its latency alone, for a before and after.
# Usage: scripts/bench-image-ab.sh ROUNDS SIZES BINARY [BINARY...]   (SIZES: e.g. 1,4)
# (build the floor first: cargo build --release --locked --example image_floor)
# With BENCH_CPUS=LIST (taskset's: `0`, `0,1`) every launch and floor runs on those CPUs
# alone, its processes with it (see scripts/bench-lockstep.sh).
set -euo pipefail
rounds=${1:?rounds}; sizes=${2:?sizes}; shift 2
[ $# -ge 1 ] || { echo "usage: $0 ROUNDS SIZES BINARY [BINARY...]" >&2; exit 2; }
root=$(cd "$(dirname "$0")/.." && pwd)
target=${CARGO_TARGET_DIR:-$root/target}
floor=$(realpath "$target/release/examples/image_floor")
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
mapfile -t graphs < <(python3 "$root/scripts/bench-image.py" --write-graphs "$work" --sizes "$sizes")
read -ra mibs <<<"${sizes//,/ }"
pin=()
if [ -n "${BENCH_CPUS:-}" ]; then
  taskset -c "$BENCH_CPUS" true || { echo "$0: BENCH_CPUS=$BENCH_CPUS: taskset cannot pin to it" >&2; exit 2; }
  pin=(taskset -c "$BENCH_CPUS")
fi
[ ${#graphs[@]} = ${#mibs[@]} ] || { echo "$0: no graphs written for sizes $sizes" >&2; exit 2; }
for r in $(seq "$rounds"); do
  for i in "${!mibs[@]}"; do
    m=${mibs[$i]}
    for b in "$@"; do
      out=$(cd "$work" && "${pin[@]}" "$b" launch "${graphs[$i]}" --processes --clock real --duration 20 --headless 2>&1 || true)
      echo "round $r $m MiB $b: $(grep -o "wire /image into 'vision': [0-9]* samples, p50 [0-9.]* µs" <<<"$out" || echo "no /image line")"
    done
    echo "round $r $m MiB bare Zenoh: $("${pin[@]}" "$floor" --count 600 --bytes $((m << 20)) | tail -1 | grep -o '"p50_us":[0-9.]*')"
  done
done
