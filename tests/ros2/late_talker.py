"""A ROS 2 graph whose publisher comes late, for `ratelab ros2 topic echo|hz|bw` on a topic
that is not published yet: nodes declared as rmw_zenoh's nodes declare themselves
(liveliness tokens, data keys, 33-byte attachments, CDR), written with independent
implementations only (PyPI `eclipse-zenoh` for the wire, `rosbags` for CDR and RIHS01
hashes). Nothing here comes from ratelab.

Usage: late_talker.py ENDPOINT DOMAIN TRIGGER
  Is the Zenoh router, listening on ENDPOINT (plays rmw_zenohd), and declares at once:
  - node /late_listener subscribing to /late (std_msgs/msg/String, rclpy's default QoS:
    reliable, volatile, keep last 10): /late has a type, and no publisher yet;
  and nothing of /later. Once the file TRIGGER exists:
  - node /late_talker publishing /late ("late 1", "late 2", ...) and /later ("later 1", ...)
    at 10 Hz each, the same type and QoS.
Prints "ready" once the first tokens are declared; runs until stdin closes (or 120 s).
"""

import json
import os
import struct
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

endpoint, domain, trigger = sys.argv[1], int(sys.argv[2]), sys.argv[3]
store = get_typestore(Stores.LATEST)
STRING = "std_msgs/msg/String"
DDS = "std_msgs::msg::dds_::String_"
HASH = store.hash_rihs01(STRING)
# rmw_zenoh's QoS string of rclpy's default (reliable, volatile, keep last 10).
DEFAULT_QOS = "::,10:,:,:,,"

conf = zenoh.Config()
conf.insert_json5("mode", json.dumps("router"))
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
zid = str(session.info.zid())
base = f"@ros2_lv/{domain}/{zid}"
held = [
    session.liveliness().declare_token(k)
    for k in [
        f"{base}/0/0/NN/%/%/late_listener",
        f"{base}/0/1/MS/%/%/late_listener/%late/{DDS}/{HASH}/{DEFAULT_QOS}",
    ]
]
done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
print("ready", flush=True)
start = time.monotonic()


def running():
    return not done.is_set() and time.monotonic() - start < 120


while running() and not os.path.exists(trigger):
    done.wait(0.02)
if running():
    held += [
        session.liveliness().declare_token(k)
        for k in [
            f"{base}/1/2/NN/%/%/late_talker",
            f"{base}/1/3/MP/%/%/late_talker/%late/{DDS}/{HASH}/{DEFAULT_QOS}",
            f"{base}/1/4/MP/%/%/late_talker/%later/{DDS}/{HASH}/{DEFAULT_QOS}",
        ]
    ]
    pubs = {t: session.declare_publisher(f"{domain}/{t}/{DDS}/{HASH}") for t in ("late", "later")}
    n = 0
    while running():
        n += 1
        for topic, pub in pubs.items():
            att = struct.pack("<qqB", n, time.time_ns(), 16) + bytes([len(topic)] * 16)
            payload = store.serialize_cdr(store.types[STRING](data=f"{topic} {n}"), STRING)
            pub.put(bytes(payload), attachment=att)
        done.wait(0.1)
for h in held:
    h.undeclare()
session.close()
