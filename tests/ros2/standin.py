"""A ROS 2 stand-in for the tests: what `ros2 topic list/echo`, `ros2 node list` and a
rmw_zenohd router would see of a ratelab graph offered with `--ros2`, written with
independent implementations only: Zenoh's official Python API (PyPI `eclipse-zenoh`) for
the wire, `rosbags` for RIHS01 hashes and CDR. Nothing here comes from ratelab.

Usage: standin.py MODE ENDPOINT DOMAIN [clock]
  MODE router: be the Zenoh router, listening on ENDPOINT (plays rmw_zenohd);
  MODE client: connect to a router at ENDPOINT (ratelab's embedded one).
With `clock`, it also declares a node 'gazebo' publishing /clock (rmw_zenoh's NN and MP
tokens), as a simulator with its own clock would. Prints "ready" once listening; when stdin closes (or after 120 s), waits a moment for the
last samples and prints one JSON report on stdout:
  nodes: [name], endpoints (every token ever declared), alive_at_end: [token], endpoints: [{kind, node, topic, type, hash, qos}],
  services: [{kind (SS/SC), node, service, type, hash, qos}],
  hash_ok: {dds type: rosbags' hash == the hash in the keys},
  topics: {topic: [{seq, source_ns, gid, value...}]} (a Log's level, name and msg; a
    ParameterEvent's node and new/changed parameters as {name: [type, value]}; an Image's pixels as data_len,
    data_sha256, data_hex and shades: {brightness: pixels}), clock_ns: [...], errors: [...]
"""

import collections
import hashlib
import json
import struct
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_typestore

mode, endpoint, domain = sys.argv[1], sys.argv[2], int(sys.argv[3])
fake_clock = sys.argv[4:] == ["clock"]
store = get_typestore(Stores.LATEST)
lock = threading.Lock()
tokens = set()  # alive now
ever = set()  # ever declared
samples = []  # (key, payload bytes, attachment bytes)


def on_token(sample):
    with lock:
        key = str(sample.key_expr)
        if sample.kind == zenoh.SampleKind.PUT:
            tokens.add(key)
            ever.add(key)
        else:
            tokens.discard(key)


def on_data(sample):
    att = sample.attachment
    # Who stamped it: a Zenoh timestamp is `<NTP64 time>/<ZID of its clock>`.
    stamp = sample.timestamp
    stamp_zid = str(stamp).split("/")[-1] if stamp is not None else None
    with lock:
        samples.append(
            (str(sample.key_expr), sample.payload.to_bytes(), att.to_bytes() if att else b"",
             stamp_zid)
        )


conf = zenoh.Config()
conf.insert_json5("mode", json.dumps(mode))
conf.insert_json5("scouting/multicast/enabled", "false")
if mode == "router":
    conf.insert_json5("listen/endpoints", json.dumps([endpoint]))
else:
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
live = session.liveliness().declare_subscriber(f"@ros2_lv/{domain}/**", on_token, history=True)
data = session.declare_subscriber(f"{domain}/**", on_data)
fakes = []
if fake_clock:
    zid = str(session.info.zid())
    clock_hash = store.hash_rihs01("rosgraph_msgs/msg/Clock")
    for key in (
        f"@ros2_lv/{domain}/{zid}/0/0/NN/%/%/gazebo",
        f"@ros2_lv/{domain}/{zid}/0/1/MP/%/%/gazebo/%clock/rosgraph_msgs::msg::dds_::Clock_/{clock_hash}/2::,1:,:,:,,",
    ):
        fakes.append(session.liveliness().declare_token(key))
print("ready", flush=True)

# Until ratelab is done.
done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
done.wait(120)
time.sleep(0.5)

errors = []
nodes, endpoints, services = [], [], []
with lock:
    seen_tokens = sorted(ever)
    alive_at_end = sorted(tokens)
    got = list(samples)


def demangle(s):
    return s.replace("%", "/")


def ros_name(dds):
    # sensor_msgs::msg::dds_::JointState_ -> sensor_msgs/msg/JointState
    pkg, kind, _, name = dds.split("::")
    return f"{pkg}/{kind}/{name[:-1]}"


for key in seen_tokens:
    parts = key.split("/")
    # @ros2_lv/<domain>/<zid>/<nid>/<eid>/<kind>/<enclave>/<ns>/<node>[/<topic>/<type>/<hash>/<qos>]
    kind = parts[5]
    if kind == "NN":
        nodes.append(parts[8])
    elif kind in ("MP", "MS"):
        endpoints.append(
            {
                "kind": kind,
                "node": parts[8],
                "topic": demangle(parts[9]),
                "type": ros_name(demangle(parts[10])),
                "hash": parts[11],
                "qos": parts[12],
                "zid": parts[2],
            }
        )
    elif kind in ("SS", "SC"):
        services.append(
            {
                "kind": kind,
                "node": parts[8],
                "service": demangle(parts[9]),
                "type": ros_name(demangle(parts[10])),
                "hash": parts[11],
                "qos": parts[12],
            }
        )
    else:
        errors.append(f"unexpected token kind {kind}: {key}")

hash_ok = {}
for e in endpoints:
    hash_ok[e["type"]] = store.hash_rihs01(e["type"]) == e["hash"]

topics, clock_ns = {}, []
for key, payload, att, stamp_zid in got:
    # <domain>/<topic...>/<dds type>/<hash>
    parts = key.split("/")
    topic = "/" + "/".join(parts[1:-2])
    ros_type = ros_name(parts[-2])
    if store.hash_rihs01(ros_type) != parts[-1]:
        errors.append(f"{key}: hash is not rosbags' {store.hash_rihs01(ros_type)}")
    if len(att) != 33 or att[16] != 16:
        errors.append(f"{key}: attachment of {len(att)} bytes")
        continue
    seq, source_ns = struct.unpack_from("<qq", att, 0)
    gid = att[17:].hex()
    msg = store.deserialize_cdr(payload, ros_type)
    if ros_type == "rosgraph_msgs/msg/Clock":
        clock_ns.append(msg.clock.sec * 1_000_000_000 + msg.clock.nanosec)
        continue
    row = {"seq": seq, "source_ns": source_ns, "gid": gid, "type": ros_type,
           "stamp_zid": stamp_zid}
    if ros_type == "sensor_msgs/msg/JointState":
        row["stamp_ns"] = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        row["name"] = list(msg.name)
        row["position"] = [float(v) for v in msg.position]
        row["velocity"] = [float(v) for v in msg.velocity]
    elif ros_type == "rcl_interfaces/msg/Log":
        row.update(level=int(msg.level), name=msg.name, msg=msg.msg,
                   stamp_ns=msg.stamp.sec * 1_000_000_000 + msg.stamp.nanosec)
    elif ros_type == "rcl_interfaces/msg/ParameterEvent":
        def values(params):
            out = {}
            for p in params:
                v = p.value
                field = {1: "bool_value", 2: "integer_value", 3: "double_value",
                         4: "string_value", 7: "integer_array_value",
                         8: "double_array_value", 9: "string_array_value"}.get(v.type)
                value = getattr(v, field) if field else None
                if hasattr(value, "tolist"):
                    value = value.tolist()
                elif isinstance(value, list):
                    value = list(value)
                out[p.name] = [int(v.type), value]
            return out
        row.update(node=msg.node, new=values(msg.new_parameters),
                   changed=values(msg.changed_parameters))
    elif ros_type == "std_msgs/msg/Float64":
        row["data"] = float(msg.data)
    elif ros_type == "sensor_msgs/msg/Image":
        row["stamp_ns"] = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        row.update(height=int(msg.height), width=int(msg.width), encoding=msg.encoding,
                   is_bigendian=int(msg.is_bigendian), step=int(msg.step))
        pixels = bytes(msg.data)
        row["data_len"] = len(pixels)
        row["data_sha256"] = hashlib.sha256(pixels).hexdigest()
        row["data_hex"] = pixels.hex()
        # How many pixels of each brightness, for the ones that occur.
        counts = collections.Counter(pixels)
        row["shades"] = {str(k): v for k, v in sorted(counts.items())}
    topics.setdefault(topic, []).append(row)

print(
    json.dumps(
        {
            "nodes": sorted(nodes),
            "endpoints": endpoints,
            "services": services,
            "hash_ok": hash_ok,
            "topics": topics,
            "clock_ns": clock_ns,
            "alive_at_end": alive_at_end,
            "errors": errors,
        }
    ),
    flush=True,
)
live.undeclare()
data.undeclare()
session.close()
