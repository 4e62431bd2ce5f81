#!/usr/bin/env bash
# The Python call against the command (issue 76, item 3), whole fresh processes alternated
# in one sitting (BENCHMARKS.md):
#   1. `python -c "import ratelab; ratelab.run(clock='virtual')"` against the installed
#      `ratelab run --clock virtual`: the same run (the chapter's graph, seed 0, 10 s).
#      Goal: the call at most 1.5x the command. Beside them, the same call with the trace's
#      arrays asked for (`.trace["step"]`): what importing NumPy adds, which a call that
#      does not ask for them no longer pays.
#   2. `python -c "import ratelab"` against `python -c pass`. Goal: at most 50 ms over it.
# Every round runs each command once, the order reversed from one round to the next (A B C,
# C B A, ...) so that drift falls on both sides; a first round warms the caches and is not
# counted. Medians of the wall time of each process, start to exit.
# Usage: scripts/bench-python-call.sh [PYTHON [ROUNDS]]
#   PYTHON: an interpreter with the wheel installed (default: python3 on PATH, e.g. an
#   activated virtual environment); the `ratelab` command is the one beside it (as
#   tests/py/test_api.py finds it), or $RATELAB when set. ROUNDS: default 21.
#   For example (the wheel as scripts/test-python.sh builds it, in a fresh environment):
#     python3 -m pip wheel --no-deps --wheel-dir /tmp/dist . && python3 -m venv /tmp/v \
#       && /tmp/v/bin/pip install /tmp/dist/ratelab-*.whl \
#       && scripts/bench-python-call.sh /tmp/v/bin/python
set -euo pipefail
python="${1:-python3}"
rounds="${2:-21}"
# An absolute path, its symlinks kept (a virtual environment's python is one).
case "$python" in
  */*) python="$(cd "$(dirname "$python")" && pwd)/$(basename "$python")" ;;
  *) python="$(command -v "$python")" ;;
esac
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cd "$work"  # away from the source tree: `import ratelab` is the installed one
"$python" - "$rounds" <<'PY'
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

rounds = int(sys.argv[1])
py = sys.executable
command = os.environ.get("RATELAB") or str(Path(py).parent / "ratelab")
found = subprocess.run([py, "-c", "import ratelab, sys; print(ratelab.__file__)"],
                       capture_output=True, text=True)
if found.returncode != 0:
    sys.exit(f"bench-python-call: {py} cannot import ratelab (install the wheel into its "
             f"environment):\n{found.stderr}")
if not os.access(command, os.X_OK):
    sys.exit(f"bench-python-call: no `ratelab` command at {command} (set RATELAB=PATH)")
print(f"python:  {py} ({sys.version.split()[0]})")
print(f"ratelab: {found.stdout.strip()}; command {command}")
print(f"{rounds} rounds, alternated, medians of whole processes")

CASES = {
    "call": [py, "-c", "import ratelab; ratelab.run(clock='virtual')"],
    "command": [command, "run", "--clock", "virtual"],
    "call+trace": [py, "-c", "import ratelab; ratelab.run(clock='virtual').trace['step']"],
    "import": [py, "-c", "import ratelab"],
    "bare": [py, "-c", "pass"],
}


def once(argv):
    start = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


times = {name: [] for name in CASES}
for name, argv in CASES.items():  # warm-up, not counted
    once(argv)
order = list(CASES)
for r in range(rounds):
    for name in order if r % 2 == 0 else order[::-1]:
        times[name].append(once(CASES[name]))

ms = {name: statistics.median(t) * 1e3 for name, t in times.items()}
spread = {name: (min(t) * 1e3, max(t) * 1e3) for name, t in times.items()}
for name, argv in CASES.items():
    low, high = spread[name]
    shown = " ".join(a if " " not in a else repr(a) for a in argv)
    print(f"  {ms[name]:8.1f} ms  (min {low:.1f}, max {high:.1f})  {name:11s} {shown}")
print(f"ratelab.run() / ratelab run:          {ms['call'] / ms['command']:.2f}  (goal <= 1.5)")
print(f"  with the trace's arrays asked for:  {ms['call+trace'] / ms['command']:.2f}  "
      f"(NumPy and the arrays: {ms['call+trace'] - ms['call']:+.1f} ms)")
print(f"import ratelab - python -c pass:      {ms['import'] - ms['bare']:.1f} ms  (goal <= 50 ms)")
print(f"ratelab run - import ratelab:         {ms['command'] - ms['import']:.1f} ms  "
      "(the command's run and summary)")
PY
