#!/usr/bin/env python3
"""A Python node reading a camera's frames from another process, in one sitting
(BENCHMARKS.md, issue 76 item 1): what reading a frame in place costs a Python node against
copying it, as it did before (a bytes field arrived as a copied `bytes`).

The graph is benches/graphs/camera-beside.toml (the chapter's loop and a camera drawing
SIZE MiB mono8 frames at 30 Hz in process `robot`) with its vision node a Python node in a
process of its own, launched with `--processes --clock real` for DURATION seconds with
Zenoh's shared memory on. Its callback reads the frame with NumPy, one byte per 4 KiB page
(so every page of the frame is touched), two ways:

  view   `np.frombuffer(img.data, np.uint8)`: the pixels where they arrived (a read-only
         view of the shared-memory buffer the camera's process wrote);
  copy   `np.frombuffer(bytes(img.data), np.uint8)`: a copy first, within the callback (a
         node got a copied `bytes` before, made outside it).

Per configuration and round: the callback's own time (perf_counter_ns around the read,
p50 and p99 over every frame), the vision node's thread CPU per tick (metrics.json's
`node_timing`), the CPU of every process of the launch (getrusage of the children), and
/image's wire latency as the launch reports it (the same transport either way). ROUNDS
rounds, the two modes alternated. Usage:
  scripts/bench-python-frame.py [--ratelab BIN] [--duration S] [--rounds N] [--sizes 1,4]
"""

import argparse
import json
import os
import re
import resource
import statistics
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = os.environ.get("CARGO_TARGET_DIR", os.path.join(ROOT, "target"))

READER = '''
import time

import numpy as np
from ratelab import Image

OUT = {out!r}
COPY = {copy!r}


class Reader:
    def __init__(self, node):
        self.total = 0
        self.out = open(OUT, "w")
        node.create_subscription(Image, "/image", self.on_image, 1)

    def on_image(self, img):
        t0 = time.perf_counter_ns()
        data = bytes(img.data) if COPY else img.data
        px = np.frombuffer(data, np.uint8)
        self.total += int(px[::4096].sum())
        took = time.perf_counter_ns() - t0
        # Every frame's time, written as it comes (outside the time measured).
        self.out.write(f"{{took}}\\n")
        self.out.flush()
'''


def children_cpu_s():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(q * len(xs)))]


def graph(folder, mib, copy):
    """camera-beside.toml with SIZE MiB frames and a Python vision node in process `vision`."""
    side = int(round(1024 * mib ** 0.5))
    text = open(os.path.join(ROOT, "benches", "graphs", "camera-beside.toml")).read()
    text = text.replace("width_px = 1024, height_px = 1024",
                        f"width_px = {side}, height_px = {side}")
    builtin = ('name = "vision"\nkind = "image_estimator"\nrate_hz = 30\n'
               'subscribes = "/image"\npublishes = "/meas"\n')
    assert builtin in text, "camera-beside.toml's vision node changed"
    mode = "copy" if copy else "view"
    text = text.replace(builtin, f'name = "vision"\nkind = "python"\nscript = "reader_{mode}.py"\n'
                                 'rate_hz = 30\nsubscribes = "/image"\nprocess = "vision"\n')
    # /meas has no publisher now.
    text = text.replace('\n[[topic]]\nname = "/meas"\ntype = "position"\ndepth = 1', "")
    took = os.path.join(folder, f"took-{mode}-{mib}.txt")
    with open(os.path.join(folder, f"reader_{mode}.py"), "w") as f:
        f.write(READER.format(out=took, copy=copy))
    path = os.path.join(folder, f"camera-python-{mode}-{mib}mib.toml")
    with open(path, "w") as f:
        f.write(text)
    return path, took


def launch(binary, duration, path, took):
    out_dir = tempfile.mkdtemp(prefix="bench-pyframe-out-")
    # A round that read nothing must not report an earlier round's times.
    if os.path.exists(took):
        os.remove(took)
    before = children_cpu_s()
    p = subprocess.run([binary, "launch", path, "--processes", "--clock", "real", "--duration",
                        str(duration), "--headless", "--out", out_dir, "--force"],
                       env={**os.environ, "RATELAB_SHARED_MEMORY": "on"}, cwd=ROOT, text=True,
                       capture_output=True, timeout=600)
    cpu = children_cpu_s() - before
    out = p.stdout + p.stderr
    if p.returncode != 0 or "BALANCED" not in out:
        sys.exit(f"the launch failed ({p.returncode}):\n{out}")
    m = re.search(r"wire /image into 'vision': (\d+) samples, p50 ([\d.]+) µs \| p99 ([\d.]+)"
                  r".*?(\d+) read in place", out)
    if not m:
        sys.exit(f"the launch did not report /image read in place:\n{out}")
    metrics = json.load(open(os.path.join(out_dir, "metrics.json")))
    vision = next(t for t in metrics["node_timing"] if t["node"] == "vision")
    ns = [int(x) for x in open(took).read().split()]
    return {"frames": int(m[1]), "in_place": int(m[4]), "wire_p50_us": float(m[2]),
            "read_p50_us": pct(ns, 0.5) / 1e3, "read_p99_us": pct(ns, 0.99) / 1e3,
            "tick_cpu_us": vision["cpu_ms"] * 1e3 / max(vision["ticks"], 1), "cpu_s": cpu}


def main():
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("--ratelab", default=os.path.join(TARGET, "release", "ratelab"))
    a.add_argument("--duration", type=int, default=20)
    a.add_argument("--rounds", type=int, default=3)
    a.add_argument("--sizes", default="1,4", help="frame sizes, MiB, comma-separated")
    o = a.parse_args()
    tmp = tempfile.mkdtemp(prefix="bench-pyframe-")
    rows = {}
    for i in range(o.rounds):
        for mib in (int(s) for s in o.sizes.split(",")):
            # Alternated, the order flipped every round.
            for copy in ((False, True) if i % 2 == 0 else (True, False)):
                path, took = graph(tmp, mib, copy)
                r = launch(o.ratelab, o.duration, path, took)
                key = (mib, "copy" if copy else "view")
                rows.setdefault(key, []).append(r)
                print(f"round {i + 1} {mib} MiB {key[1]}: {r}", flush=True)
    print()
    print("| frame | read | frames (in place) | read p50 (µs) | read p99 (µs) "
          "| vision's CPU per tick (µs) | wire p50 (µs) | CPU, every process (s) |")
    print("| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |")
    for (mib, mode), rs in sorted(rows.items()):
        cell = lambda k, fmt: ", ".join(fmt.format(r[k]) for r in rs)
        print(f"| {mib} MiB | {mode} | {cell('frames', '{}')} ({cell('in_place', '{}')}) "
              f"| {cell('read_p50_us', '{:.0f}')} | {cell('read_p99_us', '{:.0f}')} "
              f"| {cell('tick_cpu_us', '{:.0f}')} | {cell('wire_p50_us', '{:.0f}')} "
              f"| {cell('cpu_s', '{:.2f}')} |")
    print()
    med = lambda mib, mode, k: statistics.median(r[k] for r in rows[(mib, mode)])
    for mib in sorted({m for m, _ in rows}):
        print(f"{mib} MiB: read p50 view/copy {med(mib, 'view', 'read_p50_us') / med(mib, 'copy', 'read_p50_us'):.2f}×, "
              f"vision's CPU per tick view/copy {med(mib, 'view', 'tick_cpu_us') / med(mib, 'copy', 'tick_cpu_us'):.2f}×")


if __name__ == "__main__":
    main()
