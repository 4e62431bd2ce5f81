"""Reload on save, from a save to the new run on the screen (#49 item 3), for BENCHMARKS.md.

The lab runs in tmux (120x40) on the chapter's graph with a Python brain under the virtual
clock; the brain's file is saved, alternately as the scripted balancer and as a brain that
pushes nothing, and the screen is read every 5 ms until the `reloaded` line naming the new
outcome is on it.

    python3 benches/reload_latency.py [ROUNDS]   # needs tmux; CARGO_TARGET_DIR as for lab.sh
"""

import os
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BALANCER = (
    "import math\n\ndef act(obs):\n"
    "    theta = math.atan2(float(obs[3]), float(obs[2]))\n"
    "    u = 10.0 * theta + 2.0 * float(obs[4]) + 0.4 * float(obs[0]) + 0.8 * float(obs[1])\n"
    "    return max(-1.0, min(1.0, u))\n"
)
NOTHING = "def act(obs):\n    return 0.0\n"


def screen():
    return subprocess.run(["tmux", "capture-pane", "-p", "-t", "reload-bench"],
                          capture_output=True, text=True).stdout


def main():
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 10
    folder = tempfile.mkdtemp()
    brain = os.path.join(folder, "brain.py")
    with open(brain, "w") as f:
        f.write(NOTHING)
    lab = f"{ROOT}/scripts/lab.sh --clock virtual --policy {brain}"
    subprocess.run(["tmux", "new-session", "-d", "-s", "reload-bench", "-x", "120", "-y", "40",
                    lab], check=True)
    try:
        deadline = time.monotonic() + 120
        while "FELL" not in screen():
            assert time.monotonic() < deadline, screen()
            time.sleep(0.1)
        times = []
        for i in range(rounds):
            code, outcome = (BALANCER, "→ balanced") if i % 2 == 0 else (NOTHING, "→ fell")
            with open(brain, "w") as f:
                f.write(code)
            start = time.perf_counter()
            while not ("reloaded" in (s := screen()) and outcome in s):
                assert time.perf_counter() - start < 10, s
                time.sleep(0.005)
            times.append(time.perf_counter() - start)
            time.sleep(1.0)
        ms = sorted(t * 1e3 for t in times)
        print(f"save → the new run's line on the screen, {rounds} saves: median "
              f"{statistics.median(ms):.0f} ms, max {ms[-1]:.0f} ms (goal ≤ 300 ms)")
    finally:
        subprocess.run(["tmux", "kill-session", "-t", "reload-bench"])


if __name__ == "__main__":
    main()
