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
    holds an escape sequence and a newline;
  - node /gizmo publishing /gadget of a type of its own (my_pkg/msg/Gadget, hashed by
    rosbags) at 5 Hz, and serving ~/get_type_description for it as a ROS 2 node does
    (REP 2011; the description built here from rosbags' field definitions);
  - node /liar publishing /fib (my_pkg/msg/Fib) and describing it falsely (a field's type
    changed), so its description does not hash to the hash in the key.
Prints "ready" once declared; runs until stdin closes (or 120 s).
"""

import json
import struct

import numpy as np
import sys
import threading
import time

import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype
from rosbags.typesys.store import TIDMAP

endpoint, domain = sys.argv[1], int(sys.argv[2])
store = get_typestore(Stores.LATEST)
GADGET, FIB = "my_pkg/msg/Gadget", "my_pkg/msg/Fib"
store.register(get_types_from_msg(
    "string label\nfloat64[] readings\ngeometry_msgs/Vector3 offset\nint32[3] counts", GADGET))
store.register(get_types_from_msg("uint32 n\nuint64 value", FIB))
# GetTypeDescription's request and response, registered as messages (only their CDR matters).
store.register(get_types_from_msg(
    "string type_name\nstring type_hash\nbool include_type_sources", "my_pkg/msg/GtdRequest"))
store.register(get_types_from_msg(
    "bool successful\nstring failure_reason\n"
    "type_description_interfaces/TypeDescription type_description\n"
    "type_description_interfaces/TypeSource[] type_sources\n"
    "type_description_interfaces/KeyValue[] extra_information", "my_pkg/msg/GtdResponse"))
GTD_TYPE = "type_description_interfaces::srv::dds_::GetTypeDescription_"
GTD_HASH = "RIHS01_69b9c19c1021405984cc60dbbb1edceb147a6538b411d812ba6afabeed962cd5"
T = store.types


def describe(typ, lie=False):
    """`typ`'s type_description_interfaces/msg/TypeDescription, from rosbags' field
    definitions (type ids as REP 2011 numbers them); `lie`: its first field's type changed."""
    referenced = {}

    def field(name, desc):
        kind, rest = desc
        offset, capacity = 0, 0
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            (kind, rest), n = rest
            offset = 48 if desc[0] == Nodetype.ARRAY else (96 if n else 144)
            capacity = n
        nested = ""
        if kind == Nodetype.NAME:
            tid, nested = 1, rest
            individual(rest)
        else:
            tid = TIDMAP[rest[0]]
        ftype = T["type_description_interfaces/msg/FieldType"](
            type_id=offset + tid, capacity=capacity, string_capacity=0, nested_type_name=nested)
        return T["type_description_interfaces/msg/Field"](name=name, type=ftype, default_value="")

    def individual(name, top=False):
        fields = [field(n, d) for n, d in store.fielddefs[name][1]]
        one = T["type_description_interfaces/msg/IndividualTypeDescription"](
            type_name=name, fields=fields)
        if not top:
            referenced[name] = one
        return one

    top = individual(typ, top=True)
    if lie:
        top.fields[0].type.type_id = 8  # uint32 -> int64
    return T["type_description_interfaces/msg/TypeDescription"](
        type_description=top,
        referenced_type_descriptions=[referenced[k] for k in sorted(referenced)])


def serve_descriptions(node, typ, lie=False):
    def on_query(query):
        att = query.attachment.to_bytes() if query.attachment else b""
        req = store.deserialize_cdr(query.payload.to_bytes(), "my_pkg/msg/GtdRequest")
        known = req.type_name == typ
        resp = T["my_pkg/msg/GtdResponse"](
            successful=known,
            failure_reason="" if known else "unknown type",
            type_description=describe(typ, lie) if known else describe(typ),
            type_sources=[], extra_information=[])
        reply = bytes(store.serialize_cdr(resp, "my_pkg/msg/GtdResponse"))
        out = struct.pack("<qqB", struct.unpack_from("<q", att, 0)[0], time.time_ns(), 16) + att[17:]
        query.reply(service_key, reply, attachment=out)

    service_key = f"{domain}/{node}/get_type_description/{GTD_TYPE}/{GTD_HASH}"
    return session.declare_queryable(service_key, on_query, complete=True)

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
    f"@ros2_lv/{domain}/{zid}/5/10/NN/%/%/gizmo",
    f"@ros2_lv/{domain}/{zid}/5/11/MP/%/%/gizmo/%gadget/{dds(GADGET)}/{hash_of(GADGET)}/{RELIABLE_7}",
    f"@ros2_lv/{domain}/{zid}/5/12/SS/%/%/gizmo/%gizmo%get_type_description/{GTD_TYPE}/{GTD_HASH}/::,10:,:,:,,",
    f"@ros2_lv/{domain}/{zid}/6/13/NN/%/%/liar",
    f"@ros2_lv/{domain}/{zid}/6/14/MP/%/%/liar/%fib/{dds(FIB)}/{hash_of(FIB)}/{RELIABLE_7}",
    f"@ros2_lv/{domain}/{zid}/6/15/SS/%/%/liar/%liar%get_type_description/{GTD_TYPE}/{GTD_HASH}/::,10:,:,:,,",
]
services = [serve_descriptions("gizmo", GADGET), serve_descriptions("liar", FIB, lie=True)]
held = [session.liveliness().declare_token(k) for k in tokens]
pubs = {
    "cmd_vel": session.declare_publisher(key("cmd_vel", TWIST)),
    "chatter": session.declare_publisher(key("chatter", STRING)),
    "thing": session.declare_publisher(key("thing", THING)),
    "broken": session.declare_publisher(key("broken", JS)),
    "gadget": session.declare_publisher(key("gadget", GADGET)),
    "fib": session.declare_publisher(key("fib", FIB)),
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
gadget = store.serialize_cdr(
    T[GADGET](label="left arm", readings=np.array([0.5, -1.25]),
              offset=Vector3(x=1.0, y=2.0, z=3.0), counts=np.array([1, 2, 3], dtype=np.int32)),
    GADGET,
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
        put("gadget", gadget)
        put("fib", store.serialize_cdr(T[FIB](n=7, value=13), FIB))
        put("thing", bytes([0, 1, 0, 0]) + bytes(8))
        put("broken", hostile[(tick // 4) % 2])
    tick += 1
    done.wait(0.05)
for h in held:
    h.undeclare()
session.close()
