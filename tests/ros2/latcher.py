"""The latched topic of a real ROS 2 graph (`../shared/fixtures/ros2-real/kilted-ros2cli/
step2`: real rclpy over real rmw_zenoh_cpp 0.6.7, read there by the real `ros2` command),
played as rmw_zenoh_cpp's nodes publish, with independent implementations only (PyPI
`eclipse-zenoh` and its `zenoh.ext` for the wire, `rosbags` for CDR and RIHS01 hashes).
Nothing here comes from ratelab.

Usage: latcher.py ENDPOINT DOMAIN CAPTURE
  Is the Zenoh router, listening on ENDPOINT (plays rmw_zenohd), and runs:
  - node /latcher publishing /latched (std_msgs/msg/String; reliable, transient local, keep
    last 5, as the real `ros2 topic info -v /latched` showed the real node's) as
    rmw_zenoh_cpp publishes a reliable transient-local topic: a Zenoh advanced publisher
    with a cache of the depth, publisher detection and sample-miss detection (a sporadic
    heartbeat). It publishes, at once, every message CAPTURE (the capture's
    `real-other.json`) says the real node published on /latched, then nothing more;
  - node /keeper publishing /mixed (std_msgs/msg/String) reliable and transient local
    ("kept", once), and node /forgetter publishing it reliable and volatile ("forgotten",
    once): a topic whose publishers differ in durability.
Prints "ready" once all is published; runs until stdin closes (or 120 s).
"""

import json
import struct
import sys
import threading
import time

import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore

endpoint, domain, capture = sys.argv[1], int(sys.argv[2]), sys.argv[3]
with open(capture) as f:
    latched = json.load(f)["published"]["/latched"]
store = get_typestore(Stores.LATEST)
STRING = "std_msgs/msg/String"
DDS = "std_msgs::msg::dds_::String_"
HASH = store.hash_rihs01(STRING)
DEPTH = 5
# rmw_zenoh's QoS strings: reliability (empty: reliable), durability (1: transient local,
# empty: volatile), history (empty: keep last) with its depth, deadline, lifespan, liveliness.
LATCHED_QOS = f":1:,{DEPTH}:,:,:,,"
KEEPER_QOS = ":1:,1:,:,:,,"
FORGETTER_QOS = "::,10:,:,:,,"

conf = zenoh.Config()
conf.insert_json5("mode", json.dumps("router"))
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
zid = str(session.info.zid())


def key(topic):
    return f"{domain}/{topic}/{DDS}/{HASH}"


def lasting(topic, depth):
    """A reliable transient-local publisher, as rmw_zenoh_cpp makes one."""
    return zenoh.ext.declare_advanced_publisher(
        session,
        key(topic),
        cache=zenoh.ext.CacheConfig(depth),
        sample_miss_detection=zenoh.ext.MissDetectionConfig(sporadic_heartbeat=0.5),
        publisher_detection=True,
    )


tokens = [
    f"@ros2_lv/{domain}/{zid}/0/0/NN/%/%/latcher",
    f"@ros2_lv/{domain}/{zid}/0/1/MP/%/%/latcher/%latched/{DDS}/{HASH}/{LATCHED_QOS}",
    f"@ros2_lv/{domain}/{zid}/1/2/NN/%/%/keeper",
    f"@ros2_lv/{domain}/{zid}/1/3/MP/%/%/keeper/%mixed/{DDS}/{HASH}/{KEEPER_QOS}",
    f"@ros2_lv/{domain}/{zid}/2/4/NN/%/%/forgetter",
    f"@ros2_lv/{domain}/{zid}/2/5/MP/%/%/forgetter/%mixed/{DDS}/{HASH}/{FORGETTER_QOS}",
]
held = [session.liveliness().declare_token(k) for k in tokens]
pubs = {
    "latched": lasting("latched", DEPTH),
    "keeper": lasting("mixed", 1),
    "forgetter": session.declare_publisher(key("mixed")),
}
seq = {k: 0 for k in pubs}


def put(who, text):
    """`text` as a std_msgs/msg/String, with rmw_zenoh's 33-byte attachment."""
    seq[who] += 1
    gid = bytes([len(who)] * 16)
    att = struct.pack("<qqB", seq[who], time.time_ns(), 16) + gid
    payload = store.serialize_cdr(store.types[STRING](data=text), STRING)
    pubs[who].put(bytes(payload), attachment=att)


for text in latched:
    put("latched", text)
put("keeper", "kept")
put("forgetter", "forgotten")
done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
print("ready", flush=True)
done.wait(120)
for p in pubs.values():
    p.undeclare()
for h in held:
    h.undeclare()
session.close()
