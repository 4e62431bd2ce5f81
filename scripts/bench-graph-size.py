#!/usr/bin/env python3
"""What an instant of the in-process virtual run costs as the graph grows (BENCHMARKS.md).

For each size, `ratelab graph --nodes N` generates the graph (the chapter's loop and
controllers of four nodes at 10-100 Hz); `ratelab run --clock virtual` runs it for
a fixed span of run time, and the summary's wall time (the run alone, not reading the
file or building the graph) is divided by the node ticks the graph's rates give (the run
time per size is in SIZES: long enough for a second of wall time or more). Then the
same graph with every controller and extra sensor idle (`--controller-hz 0.01`: due every
100 s) shows what a node that is not due costs.

    scripts/bench-graph-size.py [BINARY] [--lockstep | --lockstep-only | --many]

With --lockstep, also `ratelab launch --processes` of generated graphs under the virtual
clock: the launcher's wall time per instant as the graph grows (8 processes) and as the
processes grow (256 nodes: enough to fill 64 processes, a controller each). With
--lockstep-only, that table alone. With --many, the same for a 1,023-node graph in 2 to 256
processes (MANY; 0.2 s of run time), each launch's whole wall time beside it: what is not
the run's instants is start-up (and the end: reports, outputs).

One sitting, one machine: compare the rows with each other, not with another machine's.
"""
import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
import tomllib

# Nodes, and the run time (s) that makes each run take a second or more of wall time.
SIZES = [(3, 3600.0), (10, 3600.0), (100, 3600.0), (1000, 600.0), (10000, 60.0)]


# The lockstep across processes: (nodes, processes, run time s), by size, then by processes.
LOCKSTEP = [(32, 8, 2.0), (100, 8, 2.0), (1000, 8, 1.0),
            (256, 2, 2.0), (256, 4, 2.0), (256, 8, 2.0), (256, 16, 2.0), (256, 32, 2.0),
            (256, 64, 2.0)]

# Hundreds of processes: a 1,023-node graph (the chapter's 3 and a controller of 4 in each
# other process, up to 256) in 2 to 256 processes, 0.2 s of run time.
MANY = [(1023, p, 0.2) for p in (2, 8, 32, 64, 128, 256)]


def run(binary, args):
    env = dict(os.environ)
    out = subprocess.run([binary, *args], check=True, capture_output=True, text=True, env=env)
    return out.stdout


def measure(binary, path, duration):
    out = run(binary, ["run", "--clock", "virtual", "--graph", path, "--duration", str(duration)])
    wall = float(re.search(r"\(([0-9.]+)s wall\)", out).group(1))
    with open(path, "rb") as f:
        graph = tomllib.load(f)
    # Each node ticks at 0, P, 2P, … up to the end: ⌊duration · rate⌋ + 1 times.
    ticks = sum(int(duration * n["rate_hz"]) + 1 for n in graph["node"])
    return wall, ticks


def lockstep(binary, nodes, processes, duration):
    """`launch --processes` of a generated graph under the virtual clock: the launcher's
    own figure of wall time per instant."""
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "g.toml")
        with open(path, "w") as f:
            f.write(run(binary, ["graph", "--nodes", str(nodes), "--processes", str(processes)]))
        t0 = time.monotonic()
        out = run(binary, ["launch", path, "--processes", "--clock", "virtual",
                           "--duration", str(duration), "--out", os.path.join(d, "out")])
        wall = time.monotonic() - t0
        found = re.search(r"in (\d+) processes", out)
        if found is None:
            sys.exit(f"the launch did not say how many processes it ran:\n{out}")
        placed = int(found.group(1))
        if placed != processes:
            sys.exit(f"{nodes} nodes were placed in {placed} processes, not {processes}")
        m = re.search(r"lockstep: (\d+) ticks at (\d+) instants, (\d+) µs of wall time per instant", out)
        return int(m.group(1)), int(m.group(2)), int(m.group(3)), wall


def main():
    p = argparse.ArgumentParser()
    p.add_argument("binary", nargs="?", default="ratelab")
    p.add_argument("--lockstep", action="store_true",
                   help="also the virtual lockstep across processes (LOCKSTEP)")
    p.add_argument("--lockstep-only", action="store_true",
                   help="only the virtual lockstep across processes")
    p.add_argument("--many", action="store_true",
                   help="only the lockstep of a 1,023-node graph in 2 to 256 processes (MANY)")
    a = p.parse_args()
    if a.many:
        across_processes(a.binary, MANY)
        return
    if not a.lockstep_only:
        in_process(a.binary)
    if a.lockstep or a.lockstep_only:
        across_processes(a.binary, LOCKSTEP)


def in_process(binary):
    print(f"| nodes | run time (s) | node ticks | wall (s) | ns per node tick | idle: wall (s) | idle: ns per instant |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    with tempfile.TemporaryDirectory() as d:
        for n, duration in SIZES:
            path = os.path.join(d, f"g{n}.toml")
            with open(path, "w") as f:
                f.write(run(binary, ["graph", "--nodes", str(n)]))
            wall, ticks = measure(binary, path, duration)
            # The same graph, its controllers and extra sensors idle: only the chapter's three
            # tick at 50 Hz; what is left is the cost of the rest being there.
            idle = os.path.join(d, f"idle{n}.toml")
            with open(idle, "w") as f:
                f.write(run(binary, ["graph", "--nodes", str(n), "--controller-hz", "0.01"]))
            idle_wall, _ = measure(binary, idle, duration)
            instants = int(duration * 50) + 1
            print(f"| {n} | {duration:.0f} | {ticks} | {wall:.2f} | {wall * 1e9 / ticks:.0f} | {idle_wall:.2f} | "
                  f"{idle_wall * 1e9 / instants:.0f} |")
            sys.stdout.flush()


def across_processes(binary, launches):
    print()
    print("| nodes | processes | node ticks | instants | µs per instant | launch wall (s) | "
          "of it not the instants (s) |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for nodes, processes, duration in launches:
        ticks, instants, us, wall = lockstep(binary, nodes, processes, duration)
        rest = wall - instants * us / 1e6
        print(f"| {nodes} | {processes} | {ticks} | {instants} | {us} | {wall:.1f} | {rest:.1f} |")
        sys.stdout.flush()


if __name__ == "__main__":
    main()
