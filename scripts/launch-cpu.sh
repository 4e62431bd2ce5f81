#!/usr/bin/env bash
# CPU an instant of the chapter's launch (issue 76 item 4), per process: a long launch of
# graphs/cartpole.toml across processes under the virtual clock, and over WINDOW_S seconds
# of it (from its run's start, at most 30 s after the launch) the user + system CPU of the
# launcher and of each of its processes (`/proc/PID/stat`), with the launch's own wall time
# per instant. Prints one line: each process's CPU in ms over the window and in µs an
# instant (the instants in the window counted from the launch's wall time per instant,
# which is its average over the whole run, window included).
# Usage: scripts/launch-cpu.sh BINARY [WINDOW_S]   (alone on the machine; default 5 s)
set -euo pipefail
bin=$(realpath "${1:?usage: $0 BINARY [WINDOW_S]}"); window=${2:-5}
root=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d)
launcher=
cleanup() {
  if [ -n "$launcher" ]; then kill -INT "$launcher" 2>/dev/null || true; wait "$launcher" 2>/dev/null || true; fi
  rm -rf "$work"
}
trap cleanup EXIT
cd "$work"
"$bin" launch "$root/graphs/cartpole.toml" --processes --clock virtual --duration 100000 \
  --headless >log 2>&1 &
launcher=$!
# The run has started once the launcher says its clock (after every process said it is ready).
robot= policy=
for _ in $(seq 300); do
  kill -0 "$launcher" 2>/dev/null || break
  robot=$(pgrep -P "$launcher" -f -- "--process robot" | head -1 || true)
  policy=$(pgrep -P "$launcher" -f -- "--process policy" | head -1 || true)
  if [ -n "$robot" ] && [ -n "$policy" ] && grep -q '^\[ratelab\] clock=' log 2>/dev/null; then break; fi
  sleep 0.1
done
[ -n "$robot" ] && [ -n "$policy" ] || { echo "$0: the launch's processes did not start" >&2; cat log >&2; exit 2; }
sleep 1
ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }
a1=$(ticks "$launcher"); r1=$(ticks "$robot"); p1=$(ticks "$policy"); t1=$(date +%s%N)
sleep "$window"
a2=$(ticks "$launcher"); r2=$(ticks "$robot"); p2=$(ticks "$policy"); t2=$(date +%s%N)
kill -INT "$launcher"; wait "$launcher" 2>/dev/null || true; launcher=
per=$(grep -o '[0-9]* µs of wall time per instant' log | grep -o '^[0-9]*' || true)
[ -n "$per" ] || { echo "$0: the launch said no wall time per instant" >&2; cat log >&2; exit 2; }
python3 - "$(getconf CLK_TCK)" "$t1" "$t2" "$per" "$a1" "$a2" "$r1" "$r2" "$p1" "$p2" <<'EOF'
import sys
tck, t1, t2, per = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
a1, a2, r1, r2, p1, p2 = map(int, sys.argv[5:])
secs = (t2 - t1) / 1e9
instants = secs * 1e6 / per
line = []
for name, x, y in (("launcher", a1, a2), ("robot", r1, r2), ("policy", p1, p2)):
    ms = (y - x) * 1000 / tck
    line.append(f"{name} {ms:.0f} ms ({ms * 1000 / instants:.0f} µs an instant)")
print(f"{per} µs of wall time per instant; over {secs:.2f} s: " + ", ".join(line))
EOF
