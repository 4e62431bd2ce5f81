"""Plays `ros2 param list / get / describe / set` against a ROS 2 graph over rmw_zenoh's
wire, and listens to `/rosout`, written with independent implementations only: Zenoh's
official Python API (PyPI `eclipse-zenoh`) for the wire, `rosbags` for CDR. Nothing here
comes from ratelab.

Usage: param_client.py ENDPOINT DOMAIN TALKER_CAPTURE NODE [NODE ...]
  ENDPOINT: a Zenoh router to connect to (client mode);
  TALKER_CAPTURE: a real rclpy node's capture (`real-rclpy-talker.json`): the services'
    type hashes are taken from its tokens, as a real ROS 2 client has them compiled in, so
    a server whose hashes differ is not reached.
For each NODE it waits (up to 20 s) for its `list_parameters` server's token, then calls,
as rmw_zenoh_cpp's clients call (a Zenoh get on `<domain>/<node>/<service>/<type>/<hash>`,
CDR request, the 33-byte attachment: sequence number, timestamp, the client's GID):
list_parameters (no prefixes, recursive), get_parameters of every name listed,
get_parameter_types of those (and again with one undeclared name), describe_parameters of the first,
set_parameters of each name (and one undeclared). It listens on /rosout meanwhile and for
2 s more. Prints "ready" once subscribed, then one JSON report on stdout:
  nodes: {NODE: {names, prefixes, values: {name: [type, value]}, types: [..], types_with_undeclared: [..],
          described: {name, type, read_only, description}, set: [{successful, reason}],
          attachments_ok: bool, seq: [..]}},
  rosout: [{node, level, msg}], errors: [...]
"""

import json
import os
import struct
import sys
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

endpoint, domain, capture = sys.argv[1], int(sys.argv[2]), sys.argv[3]
wanted = sys.argv[4:]
store = get_typestore(Stores.LATEST)
# The services' request and response messages (their .srv halves), registered as messages:
# only their CDR matters (rosbags files a `srv/` name under `srv/msg/`).
for name, text in {
    "rcl_interfaces/msg/ListParameters_Request": "string[] prefixes\nuint64 depth",
    "rcl_interfaces/msg/ListParameters_Response": "rcl_interfaces/ListParametersResult result",
    "rcl_interfaces/msg/GetParameters_Request": "string[] names",
    "rcl_interfaces/msg/GetParameters_Response": "rcl_interfaces/ParameterValue[] values",
    "rcl_interfaces/msg/GetParameterTypes_Request": "string[] names",
    "rcl_interfaces/msg/GetParameterTypes_Response": "uint8[] types",
    "rcl_interfaces/msg/DescribeParameters_Request": "string[] names",
    "rcl_interfaces/msg/DescribeParameters_Response": "rcl_interfaces/ParameterDescriptor[] descriptors",
    "rcl_interfaces/msg/SetParameters_Request": "rcl_interfaces/Parameter[] parameters",
    "rcl_interfaces/msg/SetParameters_Response": "rcl_interfaces/SetParametersResult[] results",
}.items():
    store.register(get_types_from_msg(text, name))

# The service type hashes a real node declared.
hashes = {}
for t in json.load(open(capture))["tokens_parsed"]:
    if t["kind"] == "SS":
        hashes[t["topic"].split("%")[-1]] = (t["type"], t["type_hash"])

conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
lock = threading.Lock()
rosout = []
errors = []


def on_rosout(sample):
    try:
        m = store.deserialize_cdr(sample.payload.to_bytes(), "rcl_interfaces/msg/Log")
        with lock:
            rosout.append({"node": m.name, "level": int(m.level), "msg": m.msg})
    except Exception as e:  # noqa: BLE001 - a report, not a crash
        with lock:
            errors.append(f"/rosout: {e}")


log_sub = session.declare_subscriber(f"{domain}/rosout/**", on_rosout)
print("ready", flush=True)

gid = os.urandom(16)
seq = [0]


def call(node, service, request_type, request):
    seq[0] += 1
    dds, rihs = hashes[service]
    key = f"{domain}/{node}/{service}/{dds}/{rihs}"
    att = struct.pack("<qqB", seq[0], time.time_ns(), 16) + gid
    payload = bytes(store.serialize_cdr(request, request_type))
    replies = list(session.get(key, payload=payload, attachment=att, timeout=5.0))
    ok = [r.ok for r in replies if r.ok is not None]
    if len(ok) != 1:
        raise RuntimeError(f"{key}: {len(ok)} replies")
    a = ok[0].attachment.to_bytes() if ok[0].attachment else b""
    got_seq, _, n = struct.unpack_from("<qqB", a, 0) if len(a) == 33 else (None, None, None)
    response_type = request_type.replace("_Request", "_Response")
    return store.deserialize_cdr(ok[0].payload.to_bytes(), response_type), (
        got_seq == seq[0] and n == 16 and a[17:] == gid
    )


def wait_for(node):
    deadline = time.time() + 20
    while time.time() < deadline:
        for r in session.liveliness().get(f"@ros2_lv/{domain}/**", timeout=1.0):
            if r.ok is not None and str(r.ok.key_expr).split("/")[9:10] == [
                f"%{node}%list_parameters"
            ]:
                return True
        time.sleep(0.2)
    return False


def value(v):
    field = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
             6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value",
             9: "string_array_value"}.get(v.type)
    x = getattr(v, field) if field else None
    if hasattr(x, "tolist"):
        x = x.tolist()
    elif isinstance(x, list):
        x = list(x)
    return [int(v.type), x]


T = store.types
report = {}
for node in wanted:
    if not wait_for(node):
        errors.append(f"{node}: no list_parameters server")
        continue
    try:
        oks = []
        listed, ok = call(node, "list_parameters", "rcl_interfaces/msg/ListParameters_Request",
                          T["rcl_interfaces/msg/ListParameters_Request"](prefixes=[], depth=0))
        oks.append(ok)
        names = list(listed.result.names)
        got, ok = call(node, "get_parameters", "rcl_interfaces/msg/GetParameters_Request",
                       T["rcl_interfaces/msg/GetParameters_Request"](names=names))
        oks.append(ok)
        types, ok = call(node, "get_parameter_types",
                         "rcl_interfaces/msg/GetParameterTypes_Request",
                         T["rcl_interfaces/msg/GetParameterTypes_Request"](names=names))
        oks.append(ok)
        no_types, ok = call(node, "get_parameter_types",
                            "rcl_interfaces/msg/GetParameterTypes_Request",
                            T["rcl_interfaces/msg/GetParameterTypes_Request"](
                                names=names + ["no_such_parameter"]))
        oks.append(ok)
        described, ok = call(node, "describe_parameters",
                             "rcl_interfaces/msg/DescribeParameters_Request",
                             T["rcl_interfaces/msg/DescribeParameters_Request"](names=names[:1]))
        oks.append(ok)
        d = described.descriptors[0]
        value_type = T["rcl_interfaces/msg/ParameterValue"]
        ten = value_type(type=3, bool_value=False, integer_value=0, double_value=10.0,
                         string_value="", byte_array_value=np.array([], dtype=np.uint8),
                         bool_array_value=np.array([], dtype=bool),
                         integer_array_value=np.array([], dtype=np.int64),
                         double_array_value=np.array([], dtype=np.float64),
                         string_array_value=[])
        param = T["rcl_interfaces/msg/Parameter"]
        set_, ok = call(node, "set_parameters", "rcl_interfaces/msg/SetParameters_Request",
                        T["rcl_interfaces/msg/SetParameters_Request"](
                            parameters=[param(name=n, value=ten)
                                        for n in names + ["no_such_parameter"]]))
        oks.append(ok)
        report[node] = {
            "names": names,
            "prefixes": list(listed.result.prefixes),
            "values": {n: value(v) for n, v in zip(names, got.values)},
            "types": [int(t) for t in types.types],
            "types_with_undeclared": [int(t) for t in no_types.types],
            "described": {"name": d.name, "type": int(d.type), "read_only": bool(d.read_only),
                          "description": d.description},
            "set": [{"successful": bool(r.successful), "reason": r.reason}
                    for r in set_.results],
            "attachments_ok": all(oks),
        }
    except Exception as e:  # noqa: BLE001 - a report, not a crash
        errors.append(f"{node}: {type(e).__name__}: {e}")

time.sleep(2.0)
with lock:
    heard = list(rosout)
print(json.dumps({"nodes": report, "rosout": heard, "errors": errors}), flush=True)
log_sub.undeclare()
session.close()
