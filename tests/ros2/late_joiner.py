"""A ROS 2 subscription that joins late, as rmw_zenoh_cpp makes one, written with an
independent implementation only (PyPI `eclipse-zenoh`'s `zenoh.ext`; `rosbags` for CDR).
Nothing here comes from ratelab.

Usage: late_joiner.py ENDPOINT KEY DEPTH SECONDS
  Connects (client mode) to the router at ENDPOINT and subscribes to KEY for SECONDS as a
  transient-local subscription (rmw_zenoh_cpp's: an advanced subscriber asking for history
  of at most DEPTH samples per publisher, detecting late publishers, itself detectable).
Prints "ready" at once, then one JSON report: samples: [{t (s after subscribing), seq
(the attachment's), and for rcl_interfaces/msg/Log its msg, name, level, file, function and
line}], errors: [...]
"""

import json
import struct
import sys
import threading
import time

import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore

endpoint, key, depth, seconds = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
store = get_typestore(Stores.LATEST)
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
lock = threading.Lock()
got, errors = [], []
start = time.monotonic()


def on_sample(sample):
    row = {"t": time.monotonic() - start}
    att = sample.attachment.to_bytes() if sample.attachment else b""
    row["seq"] = struct.unpack_from("<q", att, 0)[0] if len(att) == 33 else None
    if "rcl_interfaces::msg::dds_::Log_" in str(sample.key_expr):
        try:
            m = store.deserialize_cdr(sample.payload.to_bytes(), "rcl_interfaces/msg/Log")
            row.update(msg=m.msg, name=m.name, level=int(m.level), file=m.file,
                       function=m.function, line=int(m.line))
        except Exception as e:  # noqa: BLE001 - a report, not a crash
            errors.append(f"Log: {e}")
    with lock:
        got.append(row)


print("ready", flush=True)
start = time.monotonic()
sub = zenoh.ext.declare_advanced_subscriber(
    session,
    key,
    on_sample,
    history=zenoh.ext.HistoryConfig(detect_late_publishers=True, max_samples=depth),
    subscriber_detection=True,
)
time.sleep(seconds)
with lock:
    report = {"samples": list(got), "errors": list(errors)}
print(json.dumps(report), flush=True)
sub.undeclare()
session.close()
