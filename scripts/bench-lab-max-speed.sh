#!/usr/bin/env bash
# The lab at its top speed: seconds from starting the lab in tmux (120x40) to its
# "duration reached", for a virtual run of DURATION_S of the chapter's graph. It starts the
# lab, presses `>` four times (x1 -> x2 -> x4 -> x8 -> max) and polls the pane every 50 ms.
#
#   scripts/bench-lab-max-speed.sh BINARY [DURATION_S]     (default 18000)
#
# Needs tmux. Alternate two binaries in one sitting to compare them (BENCHMARKS.md).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bin="$(realpath "$1")"
duration="${2:-18000}"
session="ratelab-max-speed-$$"
export LD_LIBRARY_PATH="$root/.mujoco/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
trap 'tmux kill-session -t "$session" 2>/dev/null || true' EXIT
start=$(date +%s.%N)
tmux new-session -d -s "$session" -x 120 -y 40 \
    "cd '$root' && '$bin' --clock virtual --duration $duration 2>/dev/null"
sleep 0.3
for _ in 1 2 3 4; do tmux send-keys -t "$session" '>'; done
until tmux capture-pane -p -t "$session" | grep -q "duration reached"; do sleep 0.05; done
end=$(date +%s.%N)
tmux capture-pane -p -t "$session" | head -1 | grep -q "virtual clock max" ||
    { echo "bench-lab-max-speed: the lab was not at max speed" >&2; exit 1; }
echo "$bin $(echo "$end - $start" | bc)"
