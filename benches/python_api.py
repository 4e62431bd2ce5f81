"""The Python package's speed (#50), in one sitting, for BENCHMARKS.md: `import ratelab` in a
fresh interpreter against a bare one, and `ratelab.run(clock="virtual")` of the chapter's 10 s episode
against the command line's in-process time for the same run (`ratelab run --out DIR` run in
this process, files written, summary printed) and against the run's own wall time.

    python benches/python_api.py        # in an environment where the wheel is installed
"""

import contextlib
import os
import statistics
import subprocess
import sys
import tempfile
import time

import ratelab
from ratelab import _native

ROUNDS = 15


@contextlib.contextmanager
def quiet_stdout():
    """File descriptor 1 to /dev/null (the command line prints its summary there)."""
    sys.stdout.flush()
    saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(null)
        os.close(saved)


def median_s(argv):
    times = []
    for _ in range(ROUNDS):
        start = time.perf_counter()
        subprocess.run(argv, check=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


bare = median_s([sys.executable, "-c", "pass"])
imported = median_s([sys.executable, "-c", "import ratelab"])
print(f"python -c pass:            {bare * 1e3:7.1f} ms")
print(f"python -c 'import ratelab': {imported * 1e3:7.1f} ms  (import: {(imported - bare) * 1e3:.1f} ms)")

ratelab.run(clock="virtual")  # the first run loads MuJoCo's model
totals, walls, commands = [], [], []
with tempfile.TemporaryDirectory() as out:
    argv = ["ratelab", "run", "--clock", "virtual", "--out", out, "--force"]
    for _ in range(ROUNDS):
        start = time.perf_counter()
        run = ratelab.run(clock="virtual")
        totals.append(time.perf_counter() - start)
        walls.append(run.wall_s)
        with quiet_stdout():
            start = time.perf_counter()
            # The command line itself, in this process (as the `ratelab` command runs it).
            code = _native.main(argv)
            commands.append(time.perf_counter() - start)
        assert code == 0
total, wall, command = (statistics.median(x) for x in (totals, walls, commands))
print(f"ratelab.run(clock=virtual), 10 s: {total * 1e3:7.2f} ms")
print(f"ratelab run --out, in-process:    {command * 1e3:7.2f} ms  (ratio {total / command:.2f})")
print(f"the run itself (its wall time):   {wall * 1e3:7.2f} ms  (ratio {total / wall:.2f})")
