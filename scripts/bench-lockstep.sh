#!/usr/bin/env bash
# The lockstep against its floor (issue 76 item 4), in one sitting: an instant of the
# chapter's launch (virtual clock, DURATION_S of run time, 2 processes behind the launcher's
# router) by each BINARY, beside bare Zenoh's round trip with ratelab's session config
# (`examples/zenoh_floor`, 5,000 back to back, mean): between two peers linked directly
# ("direct") and between two clients of a router ("router", the star's own topology).
# ROUNDS rounds, the order reversed every other round. Prints one line per measure.
# Usage: scripts/bench-lockstep.sh ROUNDS DURATION_S BINARY [BINARY...]
# (build the floor first: cargo build --release --locked --example zenoh_floor)
# With BENCH_CPUS=LIST (taskset's: `0`, `0,1`) every measure runs on those CPUs alone, its
# processes with it: on a VM whose wake-ups across vCPUs are slow, one CPU takes them out of
# both figures alike (BENCHMARKS.md, the thirty-first session).
set -euo pipefail
rounds=${1:?rounds}; dur=${2:?duration}; shift 2
[ $# -ge 1 ] || { echo "usage: $0 ROUNDS DURATION_S BINARY [BINARY...]" >&2; exit 2; }
target=${CARGO_TARGET_DIR:-target}
floor=$(realpath "$target/release/examples/zenoh_floor")
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
pin=()
if [ -n "${BENCH_CPUS:-}" ]; then
  taskset -c "$BENCH_CPUS" true || { echo "$0: BENCH_CPUS=$BENCH_CPUS: taskset cannot pin to it" >&2; exit 2; }
  pin=(taskset -c "$BENCH_CPUS")
fi
measures=(direct router "$@")
one() {
  case $1 in
    direct) echo "round $2 bare round trip, direct: $("${pin[@]}" "$floor" --transport zenoh-tls --round-trips 5000 | grep -o 'mean [0-9.]* µs')" ;;
    router) echo "round $2 bare round trip, through a router: $("${pin[@]}" "$floor" --transport zenoh-router --round-trips 5000 | grep -o 'mean [0-9.]* µs')" ;;
    *) (cd "$work" && echo "round $2 $1: $("${pin[@]}" "$1" launch --processes --clock virtual --duration "$dur" --headless 2>&1 | grep -o '[0-9]* µs of wall time per instant')") ;;
  esac
}
for r in $(seq "$rounds"); do
  if [ $((r % 2)) = 1 ]; then order=("${measures[@]}"); else order=(); for ((i=${#measures[@]}-1; i>=0; i--)); do order+=("${measures[$i]}"); done; fi
  for m in "${order[@]}"; do one "$m" "$r"; done
done
