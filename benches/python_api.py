"""The Python package's speed (#50), in one sitting, for BENCHMARKS.md: `import ratelab` in a
fresh interpreter against a bare one, and `ratelab.run()` of the chapter's 10 s episode
against the run's own in-process wall time (what `ratelab run` measures of itself).

    python benches/python_api.py        # in an environment where the wheel is installed
"""

import statistics
import subprocess
import sys
import time

import ratelab

ROUNDS = 15


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

ratelab.run()  # the first run loads MuJoCo's model
totals, walls = [], []
for _ in range(ROUNDS):
    start = time.perf_counter()
    run = ratelab.run()
    totals.append(time.perf_counter() - start)
    walls.append(run.wall_s)
total, wall = statistics.median(totals), statistics.median(walls)
print(f"ratelab.run() 10 s episode: {total * 1e3:7.2f} ms; the run inside it {wall * 1e3:.2f} ms; ratio {total / wall:.2f}")
