"""The image benchmark's receiver (dataflow.yml): the latency of each payload (now minus the
send time in its first 8 bytes, CLOCK_MONOTONIC), its length checked; after FRAMES of them,
one line of JSON to REPORT: received, wrong, p50_us, p99_us, cpu_ms (this process's CPU
from its first frame to its last)."""

import json
import os
import time

from dora import Node

size = int(os.environ.get("FRAME_BYTES", 1 << 20))
frames = int(os.environ.get("FRAMES", 300))
node = Node()
lat_ns, wrong, cpu0 = [], 0, None
for event in node:
    if event["type"] != "INPUT":
        continue
    now = time.monotonic_ns()
    if cpu0 is None:
        cpu0 = time.process_time()
    pixels = event["value"].to_numpy(zero_copy_only=True)
    sent = int.from_bytes(pixels[:8].tobytes(), "little")
    if len(pixels) == size and pixels[-1] == pixels[8]:
        lat_ns.append(now - sent)
    else:
        wrong += 1
    if len(lat_ns) + wrong == frames:
        break
lat_ns.sort()
q = lambda p: lat_ns[min(len(lat_ns) - 1, int(p * len(lat_ns)))] / 1e3 if lat_ns else None
with open(os.environ["REPORT"], "w") as f:
    json.dump({"received": len(lat_ns), "wrong": wrong, "p50_us": q(0.5), "p99_us": q(0.99),
               "cpu_ms": (time.process_time() - (cpu0 or 0)) * 1e3}, f)
    f.write("\n")
