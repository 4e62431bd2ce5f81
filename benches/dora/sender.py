"""The image benchmark's sender (dataflow.yml): FRAMES payloads of FRAME_BYTES, a fresh one
at each tick, its first 8 bytes the send time on CLOCK_MONOTONIC (ns, little-endian)."""

import os
import time

import numpy as np
import pyarrow as pa
from dora import Node

size = int(os.environ.get("FRAME_BYTES", 1 << 20))
frames = int(os.environ.get("FRAMES", 300))
node = Node()
sent = 0
for event in node:
    if event["type"] != "INPUT":
        continue
    frame = np.full(size, sent % 251, dtype=np.uint8)
    frame[:8] = np.frombuffer(time.monotonic_ns().to_bytes(8, "little"), np.uint8)
    node.send_output("image", pa.array(frame))
    sent += 1
    if sent == frames:
        break
