"""The edge cases of a real ROS 2 graph (`../shared/fixtures/ros2-real/kilted-ros2cli/step2/
edge`: real rclpy over real rmw_zenoh_cpp 0.6.7, read there by the real `ros2` command),
declared as rmw_zenoh_cpp's nodes declare themselves, with independent implementations only
(PyPI `eclipse-zenoh` for the wire, `rosbags` for RIHS01 hashes). Nothing here comes from
ratelab.

Usage: edges.py ENDPOINT DOMAIN TALKER_CAPTURE
  Is the Zenoh router, listening on ENDPOINT (plays rmw_zenohd), and declares the liveliness
  tokens of the capture's graph, as `ros2 node list -a`, `topic list -t
  --include-hidden-topics` and `node info` showed it:
  - node /_hidden_node (hidden: its name begins with `_`) publishing /_secret
    (std_msgs/msg/String), a hidden topic;
  - two nodes named /dup: the first (node id 1) publishing /dup/private (String) and
    /parameter_events and serving the parameter services, as the real `node info /dup`
    showed the one it chose; the second (node id 2) publishing /mixed as std_msgs/msg/Int32,
    and /rosout;
  - node /ns/talker publishing and subscribing to /ns/chatter (String);
  - node /talker publishing /mixed as std_msgs/msg/String: /mixed has two types.
  Every node but the /dup pair also has the endpoints every rclpy node declares (/rosout,
  /parameter_events, the seven parameter and type description services), their types,
  hashes and QoS copied from a real rclpy node's tokens (TALKER_CAPTURE:
  `real-rclpy-talker.json`). Nothing is published.
Prints "ready" once declared; runs until stdin closes (or 120 s).
"""

import json
import sys
import threading

import zenoh
from rosbags.typesys import Stores, get_typestore

endpoint, domain, talker_capture = sys.argv[1], int(sys.argv[2]), sys.argv[3]
store = get_typestore(Stores.LATEST)
STRING, INT32 = "std_msgs/msg/String", "std_msgs/msg/Int32"
# rmw_zenoh's QoS string of rclpy's default (reliable, volatile, keep last 10), as the real
# talker's /chatter token has it.
DEFAULT_QOS = "::,10:,:,:,,"


def dds(typ):
    """`pkg/msg/T` as rmw_zenoh names it in keys and tokens: `pkg::msg::dds_::T_`."""
    pkg, kind, name = typ.split("/")
    return f"{pkg}::{kind}::dds_::{name}_"


def mangled(name):
    """A name in a token: each `/` as `%`; the root namespace as `%` alone."""
    return name.replace("/", "%") if name != "/" else "%"


# The endpoints a real rclpy node declares besides its own topics, from its tokens: by
# (kind, name), its type, hash and QoS, and whether the name is under the node's (a service).
with open(talker_capture) as f:
    events = json.load(f)["token_events"]
standard = {}
for event in events:
    parts = event["key"].split("/")
    if event["kind"] != "SampleKind.PUT" or len(parts) != 13:
        continue
    kind, node_name, topic = parts[5], parts[8], parts[9]
    typ, hsh, qos = parts[10], parts[11], parts[12]
    if kind == "MP" and topic in ("%rosout", "%parameter_events"):
        name, service = topic, False
    elif kind == "SS" and topic.startswith(f"%{node_name}%"):
        name, service = topic[len(node_name) + 1:], True
    else:
        continue
    standard[(kind, name)] = dict(kind=kind, name=name, typ=typ, hsh=hsh, qos=qos, service=service)
assert len(standard) == 9, f"the real node's 2 topics and 7 services, got {sorted(standard)}"

conf = zenoh.Config()
conf.insert_json5("mode", json.dumps("router"))
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
zid = str(session.info.zid())
tokens = []
next_entity = [100]


def node(nid, namespace, name, own, rosout=True, events=True, services=True):
    """Node `namespace`/`name` (node id `nid`), its `own` endpoints [(kind, topic, type)]
    and the standard ones asked for, as tokens."""
    base = f"@ros2_lv/{domain}/{zid}/{nid}"
    ns = mangled(namespace)
    full = namespace.rstrip("/") + "/" + name
    tokens.append(f"{base}/{nid}/NN/%/{ns}/{name}")

    def endpoint_token(kind, topic, typ, hsh, qos):
        next_entity[0] += 1
        tokens.append(f"{base}/{next_entity[0]}/{kind}/%/{ns}/{name}/{topic}/{typ}/{hsh}/{qos}")

    for kind, topic, typ in own:
        endpoint_token(kind, mangled(topic), dds(typ), store.hash_rihs01(typ), DEFAULT_QOS)
    for e in standard.values():
        if e["service"]:
            if services:
                endpoint_token(e["kind"], mangled(full) + e["name"], e["typ"], e["hsh"], e["qos"])
        elif (e["name"] == "%rosout" and rosout) or (e["name"] == "%parameter_events" and events):
            endpoint_token(e["kind"], e["name"], e["typ"], e["hsh"], e["qos"])


node(0, "/", "_hidden_node", [("MP", "/_secret", STRING)])
node(1, "/", "dup", [("MP", "/dup/private", STRING)], rosout=False)
node(2, "/", "dup", [("MP", "/mixed", INT32)], events=False, services=False)
node(3, "/ns", "talker", [("MP", "/ns/chatter", STRING), ("MS", "/ns/chatter", STRING)])
node(4, "/", "talker", [("MP", "/mixed", STRING)])
held = [session.liveliness().declare_token(k) for k in tokens]
done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
print("ready", flush=True)
done.wait(120)
for h in held:
    h.undeclare()
session.close()
