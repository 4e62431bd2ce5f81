#!/usr/bin/env python3
"""A camera's frames across two processes, in one sitting (BENCHMARKS.md, issues 51 and 76):
1 MiB (and 4 MiB, --sizes) payloads at 30 Hz for DURATION seconds, one way, latency from the
send to the receiver's callback on the host's CLOCK_MONOTONIC (p50, p99 over every frame),
and the CPU time of every process of the run (getrusage of the children, start-up included).

  ratelab   `ratelab launch benches/graphs/camera-beside.toml --processes --clock real`:
            /image from `robot` to `vision`, its wire latency as the launch reports it
            (sent before the payload is encoded, taken once it is in the subscriber's queue).
            The CPU is the whole graph's (MuJoCo, five nodes, the drawing and the vision).
  bare      examples/image_floor.rs: bare Zenoh opened as ratelab opens it (mutual TLS,
            access control, ratelab's runtime threads), nothing else of ratelab's.
  chapter   the chapter's graph alone, launched the same way: the CPU the camera adds is
            ratelab's figure less this one.
  one       the camera graph and the chapter's in one process (no --processes): what
            crossing costs ratelab in CPU is (camera − one) − (chapter − chapter in one),
            per frame, against bare Zenoh's CPU per frame.
            The vision node ticks half a period after the camera (--vision-phase-ms, its
            `start_ms`), as the chapter's phase offsets teach a consumer to: ticking with the
            camera, its scan of the last frame (about 1 ms at 4 MiB) ran on this 2-core host
            while the next one crossed, and was counted in the wire's latency (bare Zenoh's
            subscriber does no work). --aligned-too measures that case as well.
  dora      dora-rs 1.1 (`dora run benches/dora/dataflow.yml`, two Python nodes; optional:
            --dora DIR names a folder with its `dora` and a Python that imports `dora`,
            e.g. a venv with `pip install dora-rs-cli==1.1.0 dora-rs==1.1.0 pyarrow numpy`).

ratelab and bare run with Zenoh's shared memory on and off (RATELAB_SHARED_MEMORY), each
configuration ROUNDS times, alternated. Usage:
  scripts/bench-image.py [--ratelab BIN] [--floor BIN] [--dora DIR] [--duration S] [--rounds N]
                         [--sizes 1,4] [--no-off] [--vision-phase-ms MS] [--aligned-too]
  scripts/bench-image.py --write-graphs DIR [--sizes 1,4] [--vision-phase-ms MS]
            writes the camera graph of each size into DIR, prints their paths and stops
            (scripts/bench-image-ab.sh launches them)
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


def children_cpu_s():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(cmd, env=None, cwd=ROOT):
    """Run `cmd`; its output and the CPU seconds it and its children used."""
    before = children_cpu_s()
    p = subprocess.run(cmd, env={**os.environ, **(env or {})}, cwd=cwd, text=True,
                       capture_output=True, timeout=600)
    if p.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({p.returncode}):\n{p.stdout}\n{p.stderr}")
    return p.stdout + p.stderr, children_cpu_s() - before


def camera_graph(mib, folder, vision_phase_ms):
    """benches/graphs/camera-beside.toml with frames of `mib` MiB (a square mono8 frame), its
    vision node's ticks `vision_phase_ms` after the camera's (its `start_ms`; 0: with them)."""
    side = int(round(1024 * mib ** 0.5))
    text = open(os.path.join(ROOT, "benches", "graphs", "camera-beside.toml")).read()
    text = text.replace("width_px = 1024, height_px = 1024",
                        f"width_px = {side}, height_px = {side}")
    vision = 'name = "vision"\nkind = "image_estimator"\nrate_hz = 30\n'
    assert vision in text, "camera-beside.toml's vision node changed"
    if vision_phase_ms:
        text = text.replace(vision, f"{vision}start_ms = {vision_phase_ms}\n")
    path = os.path.join(folder, f"camera-{mib}mib-phase{vision_phase_ms}.toml")
    with open(path, "w") as f:
        f.write(text)
    return path


def ratelab(binary, duration, shm, graph):
    out, cpu = run([binary, "launch", graph, "--processes",
                    "--clock", "real", "--duration", str(duration), "--headless"],
                   {"RATELAB_SHARED_MEMORY": shm})
    m = re.search(r"wire /image into 'vision': (\d+) samples, p50 ([\d.]+) µs \| p99 ([\d.]+)", out)
    if not m or "BALANCED" not in out:
        sys.exit(f"the launch did not report /image or did not balance:\n{out}")
    return {"frames": int(m[1]), "p50_us": float(m[2]), "p99_us": float(m[3]), "cpu_s": cpu}


def chapter(binary, duration, graph=None, processes=True):
    """A graph (the chapter's by default) across processes or in one, for its CPU alone."""
    out, cpu = run([binary, "launch", *([graph] if graph else []),
                    *(["--processes"] if processes else []), "--clock", "real", "--duration",
                    str(duration), "--headless"])
    if "BALANCED" not in out:
        sys.exit(f"the chapter's graph did not balance:\n{out}")
    return {"frames": 0, "p50_us": 0.0, "p99_us": 0.0, "cpu_s": cpu}


def bare(binary, duration, shm, mib):
    out, cpu = run([binary, "--count", str(30 * duration), "--bytes", str(mib << 20)],
                   {"RATELAB_SHARED_MEMORY": shm})
    r = json.loads(out.strip().splitlines()[-1])
    if r["wrong"] or r["received"] != r["sent"]:
        sys.exit(f"bare Zenoh lost or garbled frames: {r}")
    return {"frames": r["received"], "p50_us": r["p50_us"], "p99_us": r["p99_us"], "cpu_s": cpu}


def dora(folder, duration, mib):
    with tempfile.TemporaryDirectory() as tmp:
        report = os.path.join(tmp, "report.json")
        env = {"PATH": folder + os.pathsep + os.environ["PATH"],
               "VIRTUAL_ENV": os.path.dirname(folder), "REPORT": report,
               "FRAMES": str(30 * duration), "FRAME_BYTES": str(mib << 20)}
        _, cpu = run([os.path.join(folder, "dora"), "run", "dataflow.yml", "--stop-after",
                      f"{duration + 30}s"], env, cwd=os.path.join(ROOT, "benches", "dora"))
        r = json.load(open(report))
    if r["wrong"]:
        sys.exit(f"dora garbled frames: {r}")
    return {"frames": r["received"], "p50_us": r["p50_us"], "p99_us": r["p99_us"], "cpu_s": cpu}


def main():
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("--ratelab", default=os.path.join(TARGET, "release", "ratelab"))
    a.add_argument("--floor", default=os.path.join(TARGET, "release", "examples", "image_floor"))
    a.add_argument("--dora", help="a folder with dora-rs 1.1's `dora` and its Python")
    a.add_argument("--duration", type=int, default=20)
    a.add_argument("--rounds", type=int, default=3)
    a.add_argument("--sizes", default="1,4", help="frame sizes, MiB, comma-separated")
    a.add_argument("--no-off", action="store_true", help="shared memory on only")
    a.add_argument("--vision-phase-ms", type=float, default=16.5,
                   help="the vision node's ticks this long after the camera's (0: with them)")
    a.add_argument("--aligned-too", action="store_true",
                   help="also ratelab with the vision node ticking with the camera")
    a.add_argument("--write-graphs", metavar="DIR",
                   help="write the camera graph of each size into DIR, print their paths, stop")
    o = a.parse_args()
    try:
        sizes = [int(m) for m in o.sizes.split(",")]
    except ValueError:
        a.error(f"--sizes: whole MiB, comma-separated (1,4), not {o.sizes!r}")
    if o.write_graphs:
        os.makedirs(o.write_graphs, exist_ok=True)
        for mib in sizes:
            print(camera_graph(mib, o.write_graphs, o.vision_phase_ms))
        return
    shms = ("on",) if o.no_off else ("on", "off")
    rows = {}
    tmp = tempfile.mkdtemp(prefix="bench-image-")
    graphs = {mib: camera_graph(mib, tmp, o.vision_phase_ms) for mib in sizes}
    aligned = {mib: camera_graph(mib, tmp, 0) for mib in sizes}

    def add(key, r, label):
        rows.setdefault(key, []).append(r)
        print(f"round {i + 1} {label}: {r}", flush=True)

    for i in range(o.rounds):
        for mib in sizes:
            for shm in shms:
                add((f"ratelab, {mib} MiB", shm), ratelab(o.ratelab, o.duration, shm, graphs[mib]),
                    f"ratelab {mib} MiB shm {shm}")
                add((f"bare Zenoh, {mib} MiB", shm), bare(o.floor, o.duration, shm, mib),
                    f"bare {mib} MiB shm {shm}")
                if o.aligned_too and o.vision_phase_ms:
                    add((f"ratelab, {mib} MiB, vision ticking with the camera", shm),
                        ratelab(o.ratelab, o.duration, shm, aligned[mib]),
                        f"ratelab {mib} MiB shm {shm}, vision aligned")
            add((f"ratelab, {mib} MiB, one process", "-"),
                chapter(o.ratelab, o.duration, graphs[mib], processes=False),
                f"ratelab {mib} MiB in one process")
            if o.dora:
                add((f"dora-rs 1.1 (Python nodes), {mib} MiB", "dora's own"),
                    dora(o.dora, o.duration, mib), f"dora {mib} MiB")
        add(("ratelab, the chapter's graph alone (no camera)", "-"),
            chapter(o.ratelab, o.duration), "chapter")
        add(("ratelab, the chapter's graph alone, one process", "-"),
            chapter(o.ratelab, o.duration, processes=False), "chapter in one process")
    print()
    print("| transport | shared memory | frames | p50 (µs) | p99 (µs) | CPU, every process (s) |")
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for (name, shm), rs in rows.items():
        cell = lambda k, fmt: ", ".join(fmt.format(r[k]) for r in rs)
        med = statistics.median(r["p50_us"] for r in rs)
        print(f"| {name} | {shm} | {cell('frames', '{}')} | {cell('p50_us', '{:.0f}')} "
              f"(median {med:.0f}) | {cell('p99_us', '{:.0f}')} | {cell('cpu_s', '{:.2f}')} |")
    # The CPU a frame's crossing costs, medians: ratelab's is what crossing adds to the same
    # graphs in one process; bare Zenoh's is all of its CPU (it does nothing else).
    med = lambda key: statistics.median(r["cpu_s"] for r in rows[key])
    chapter_cost = (med(("ratelab, the chapter's graph alone (no camera)", "-"))
                    - med(("ratelab, the chapter's graph alone, one process", "-")))
    frames = 30 * o.duration
    print()
    for mib in sizes:
        crossing = (med((f"ratelab, {mib} MiB", "on"))
                    - med((f"ratelab, {mib} MiB, one process", "-")) - chapter_cost)
        bare_cpu = med((f"bare Zenoh, {mib} MiB", "on"))
        print(f"{mib} MiB, shared memory on: crossing CPU per frame, ratelab "
              f"{crossing / frames * 1e6:.0f} µs, bare Zenoh {bare_cpu / frames * 1e6:.0f} µs "
              f"({crossing / bare_cpu:.2f}×); p50 ratelab/bare "
              f"{statistics.median(r['p50_us'] for r in rows[(f'ratelab, {mib} MiB', 'on')]) / statistics.median(r['p50_us'] for r in rows[(f'bare Zenoh, {mib} MiB', 'on')]):.2f}×")

if __name__ == "__main__":
    main()
