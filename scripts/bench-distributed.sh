#!/usr/bin/env bash
# The process boundary's cost, measured side by side in one sitting (BENCHMARKS.md, issue 13):
#   1. over-the-wire latency per message at 50 Hz and at 1 kHz (p50/p99/max), and losses;
#   2. the virtual lockstep's cost per granted tick and per instant;
#   3. the transport's floor in the same sitting: bare Zenoh (ratelab's session config) and a
#      bare TCP socket, one way at 50 Hz and 1 kHz and round trips back to back
#      (examples/zenoh_floor.rs);
# (Zenoh's default runtime threads, once its part 4, are no longer compared: they run
# Zenoh's TLS receive and send on two threads, which corrupts memory, eclipse-zenoh/zenoh#2557,
# and ratelab refuses them for a graph's sessions.)
# Usage: scripts/bench-distributed.sh [RATELAB_BINARY [ZENOH_FLOOR_BINARY]]
#        (default: cargo's release builds; `cargo build --release --all-targets` builds both)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin="${1:-${CARGO_TARGET_DIR:-$root/target}/release/ratelab}"
floor="${2:-${CARGO_TARGET_DIR:-$root/target}/release/examples/zenoh_floor}"
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
cd "$root"
echo "== 50 Hz, real clock, 10 s (the chapter's graph: robot [sensor, actuator] + policy)"
"$bin" launch --processes --clock real --duration 10 --out "$out/50" | grep -E "wire|BALANCED|fell|topics"
echo "== 1 kHz sensor and policy, real clock, 10 s"
"$bin" launch --processes --clock real --duration 10 --rate sensor=1000 --rate policy=1000 \
  --out "$out/1k" | grep -E "wire|BALANCED|fell|topics"
python3 - "$out/1k/metrics.json" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
for name, t in m["topics"].items():
    print(f"   {name}: published {t['published']}, lost {t.get('lost', 0)}, dropped {t['dropped']}")
print(f"   sensor ticks {m['nodes']['sensor']['ticks']}, policy ticks {m['nodes']['policy']['ticks']}")
PY
echo "== virtual lockstep, 60 s at 50 Hz (3001 instants)"
"$bin" launch --processes --clock virtual --duration 60 --out "$out/v" | grep -E "lockstep|wall"
echo "== the same run in one process"
"$bin" run --clock virtual --duration 60 | grep -E "wall"
echo "== the transport's floor: bare Zenoh and bare TCP, nothing of ratelab's on the path"
"$floor"
