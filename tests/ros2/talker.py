"""A ROS 2 graph that is not ratelab's, for `ratelab ros2`'s tests: nodes publishing as
rmw_zenoh's nodes do (liveliness tokens, data keys, 33-byte attachments, CDR), written
with independent implementations only (PyPI `eclipse-zenoh` for the wire, `rosbags` for
CDR and RIHS01 hashes). Nothing here comes from ratelab.

Usage: talker.py ENDPOINT DOMAIN
  Is the Zenoh router, listening on ENDPOINT (plays rmw_zenohd), and runs:
  - node /demo/talker publishing /cmd_vel (geometry_msgs/msg/Twist, linear.x 0.5,
    angular.z -0.25) at 20 Hz, reliable, keep-last 7, and /chatter (std_msgs/msg/String,
    "hello world 1", "hello world 2", ...) at 10 Hz;
  - node /listener subscribing to /chatter, best effort, keep-last 1, deadline 100 ms;
  - node /mystery publishing /thing of a type nobody describes (my_pkg/msg/Thing, a
    made-up hash), 12 bytes at 5 Hz;
  - node /hostile publishing /broken (sensor_msgs/msg/JointState) with payloads that do not
    decode (truncated; a sequence claiming 2^32 - 1 elements) at 5 Hz; and a node whose name
    holds an escape sequence and a newline.
Prints "ready" once declared; runs until stdin closes (or 120 s).
"""

import json
import struct
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

endpoint, domain = sys.argv[1], int(sys.argv[2])
store = get_typestore(Stores.LATEST)
TWIST, STRING, JS = "geometry_msgs/msg/Twist", "std_msgs/msg/String", "sensor_msgs/msg/JointState"
THING, THING_HASH = "my_pkg/msg/Thing", "RIHS01_" + "ab" * 32


def dds(t):
    pkg, _, short = t.split("/")
    return f"{pkg}::msg::dds_::{short}_"


def hash_of(t):
    return THING_HASH if t == THING else store.hash_rihs01(t)


def key(topic, t):
    return f"{domain}/{topic}/{dds(t)}/{hash_of(t)}"


conf = zenoh.Config()
conf.insert_json5("mode", json.dumps("router"))
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
zid = str(session.info.zid())

RELIABLE_7 = "1::,7:,:,:,,"
BEST_EFFORT_1_DL = "2::,1:0,100000000:,:,,"
tokens = [
    f"@ros2_lv/{domain}/{zid}/0/0/NN/%/%demo/talker",
    f"@ros2_lv/{domain}/{zid}/0/1/MP/%/%demo/talker/%cmd_vel/{dds(TWIST)}/{hash_of(TWIST)}/{RELIABLE_7}",
    f"@ros2_lv/{domain}/{zid}/0/2/MP/%/%demo/talker/%chatter/{dds(STRING)}/{hash_of(STRING)}/{RELIABLE_7}",
    f"@ros2_lv/{domain}/{zid}/1/3/NN/%/%/listener",
    f"@ros2_lv/{domain}/{zid}/1/4/MS/%/%/listener/%chatter/{dds(STRING)}/{hash_of(STRING)}/{BEST_EFFORT_1_DL}",
    f"@ros2_lv/{domain}/{zid}/2/5/NN/%/%/mystery",
    f"@ros2_lv/{domain}/{zid}/2/6/MP/%/%/mystery/%thing/{dds(THING)}/{hash_of(THING)}/{RELIABLE_7}",
    f"@ros2_lv/{domain}/{zid}/3/7/NN/%/%/hostile",
    f"@ros2_lv/{domain}/{zid}/3/8/MP/%/%/hostile/%broken/{dds(JS)}/{hash_of(JS)}/{RELIABLE_7}",
    f"@ros2_lv/{domain}/{zid}/4/9/NN/%/%/evil\x1b[2J\nnode",
]
held = [session.liveliness().declare_token(k) for k in tokens]
pubs = {
    "cmd_vel": session.declare_publisher(key("cmd_vel", TWIST)),
    "chatter": session.declare_publisher(key("chatter", STRING)),
    "thing": session.declare_publisher(key("thing", THING)),
    "broken": session.declare_publisher(key("broken", JS)),
}
seq = {k: 0 for k in pubs}


def put(topic, payload):
    seq[topic] += 1
    gid = bytes([len(topic)] * 16)
    att = struct.pack("<qqB", seq[topic], time.time_ns(), 16) + gid
    pubs[topic].put(bytes(payload), attachment=att)


Vector3 = store.types["geometry_msgs/msg/Vector3"]
twist = store.serialize_cdr(
    store.types[TWIST](linear=Vector3(x=0.5, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=-0.25)),
    TWIST,
)
hostile = [
    bytes([0, 1, 0, 0, 1, 2]),  # truncated inside the header's stamp
    bytes([0, 1, 0, 0]) + bytes(8) + struct.pack("<I", 0xFFFFFFFF),  # frame_id of 2^32 - 1 bytes
]
done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
print("ready", flush=True)
tick, start = 0, time.monotonic()
while not done.is_set() and time.monotonic() - start < 120:
    put("cmd_vel", twist)
    if tick % 2 == 0:
        n = tick // 2 + 1
        put("chatter", store.serialize_cdr(store.types[STRING](data=f"hello world {n}"), STRING))
    if tick % 4 == 0:
        put("thing", bytes([0, 1, 0, 0]) + bytes(8))
        put("broken", hostile[(tick // 4) % 2])
    tick += 1
    done.wait(0.05)
for h in held:
    h.undeclare()
session.close()
