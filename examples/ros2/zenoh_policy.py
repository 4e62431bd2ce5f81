"""An external policy with no ROS 2 installation: the chapter's scripted balancer as a ROS 2
node runs it under rmw_zenoh, written with two pip packages, `eclipse-zenoh` (the wire) and
`rosbags` (CDR and RIHS01 hashes). Nothing here comes from ratelab; the tests run this file.

Try it (two terminals; ratelab runs the Zenoh router and waits 10 s for the node):

    python3 -m venv .venv-zenoh && . .venv-zenoh/bin/activate
    pip install eclipse-zenoh==1.10.2 rosbags
    ratelab run --graph graphs/cartpole-external.toml --ros2 --clock virtual    # first
    python3 examples/ros2/zenoh_policy.py tcp/localhost:7447 0 50              # within 10 s

Under the virtual clock the run's metrics.json and trace.csv are byte-identical to the
built-in policy's (`ratelab run --clock virtual --out DIR`): it computes the same force from
the same observation at the same instants (docs/ros2.md, "ROS 2 nodes in the graph").

Usage: zenoh_policy.py ENDPOINT DOMAIN RATE_HZ [--name N] [--type float32] [--mute]
  connects as a Zenoh client to the router at ENDPOINT, declares rmw_zenoh's tokens for a
  node N (default `policy`) subscribing to /obs (sensor_msgs/msg/JointState) and publishing
  /action (std_msgs/msg/Float64; with --type float32, std_msgs/msg/Float32: the wrong type),
  and follows /clock as examples/ros2/balancer_node.py does (a /clock subscription, not an
  rclpy timer, which under sim time would first fire one period after 0): when the clock
  reaches its next tick (every 1/RATE_HZ from 0), it publishes the balancer's force from
  the newest /obs.
  --mute: declares everything, publishes nothing. --double: publishes each tick's message
  twice (breaks the one-message-per-tick contract). --forge: also declares what a hostile
  peer on the domain could: a publisher token of the same node and topic whose type name
  holds an escape sequence, and one of another type (Float32).
Prints "ready" once declared; runs until stdin closes (or 120 s), then prints one JSON
line: {"published": n, "clock_msgs": n, "obs_msgs": n}.
"""

import json
import struct
import sys
import threading

import zenoh
from rosbags.typesys import Stores, get_typestore

endpoint, domain, rate_hz = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
args = sys.argv[4:]
name = args[args.index("--name") + 1] if "--name" in args else "policy"
wrong = "--type" in args and args[args.index("--type") + 1] == "float32"
mute = "--mute" in args
double = "--double" in args
store = get_typestore(Stores.LATEST)
GEAR_N = 10.0  # the cartpole's motor: newtons per unit of action
period_ns = round(1e9 / rate_hz)

JS, F64, F32, CLOCK = (
    "sensor_msgs/msg/JointState",
    "std_msgs/msg/Float64",
    "std_msgs/msg/Float32",
    "rosgraph_msgs/msg/Clock",
)
out_type = F32 if wrong else F64


def dds(t):
    pkg, _, short = t.split("/")
    return f"{pkg}::msg::dds_::{short}_"


def data_key(topic, t):
    return f"{domain}/{topic}/{dds(t)}/{store.hash_rihs01(t)}"


conf = zenoh.Config()
conf.insert_json5("mode", json.dumps("client"))
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
session = zenoh.open(conf)
zid = str(session.info.zid())

lock = threading.Lock()
state = {"obs": None, "next_ns": 0, "last_ns": 0, "published": 0, "clock_msgs": 0, "obs_msgs": 0, "seq": 0}
gid = bytes(range(16))
pub = session.declare_publisher(data_key("action", out_type))


def balance(js):
    # The chapter's scripted balancer, in ratelab's order of operations (float64), its
    # action rounded to float32 as the chapter's action is, times the gear.
    x, th = js.position[0], js.position[1]
    xd, thd = js.velocity[0], js.velocity[1]
    u = 10.0 * th + 2.0 * thd + 0.4 * x + 0.8 * xd
    u = max(-1.0, min(1.0, u))
    u = struct.unpack("<f", struct.pack("<f", u))[0]
    return u * GEAR_N


def on_obs(sample):
    js = store.deserialize_cdr(sample.payload.to_bytes(), JS)
    with lock:
        state["obs"] = js
        state["obs_msgs"] += 1


def on_clock(sample):
    c = store.deserialize_cdr(sample.payload.to_bytes(), CLOCK)
    t = c.clock.sec * 1_000_000_000 + c.clock.nanosec
    with lock:
        state["clock_msgs"] += 1
        if t < state["last_ns"]:
            # Time jumped back (a new run, or the lab's reset, starts at 0): as ROS 2 resets
            # its timers on a backward jump, the next tick is due at once.
            state["next_ns"] = t
        state["last_ns"] = t
        if t < state["next_ns"]:
            return
        while state["next_ns"] <= t:  # a ROS 2 timer: the next call after now
            state["next_ns"] += period_ns
        if mute or state["obs"] is None:
            return
        force = balance(state["obs"])
        msg_cls = store.types[out_type]
        payload = store.serialize_cdr(msg_cls(data=force), out_type)
        for _ in range(2 if double else 1):
            state["seq"] += 1
            att = struct.pack("<qqB", state["seq"], 0, 16) + gid
            pub.put(bytes(payload), attachment=att)
            state["published"] += 1


OBS_KEY, CLOCK_KEY = data_key("obs", JS), data_key("clock", CLOCK)


def on_data(sample):
    # One subscriber for both topics: one callback thread, so samples are handled in the
    # order they arrived (zenoh-python runs each subscriber's callbacks on its own thread).
    key = str(sample.key_expr)
    if key == OBS_KEY:
        on_obs(sample)
    elif key == CLOCK_KEY:
        on_clock(sample)


sub = session.declare_subscriber(f"{domain}/**", on_data)
qos = "1::,1:,:,:,,"
tokens = [
    f"@ros2_lv/{domain}/{zid}/0/0/NN/%/%/{name}",
    f"@ros2_lv/{domain}/{zid}/0/1/MS/%/%/{name}/%obs/{dds(JS)}/{store.hash_rihs01(JS)}/{qos}",
    f"@ros2_lv/{domain}/{zid}/0/2/MP/%/%/{name}/%action/{dds(out_type)}/{store.hash_rihs01(out_type)}/{qos}",
]
if "--forge" in args:
    evil = "std_msgs::msg::dds_::Float64\x1b[2J\x1b]0;pwned\x07_"
    tokens += [
        f"@ros2_lv/{domain}/{zid}/0/3/MP/%/%/{name}/%action/{evil}/{store.hash_rihs01(F64)}/{qos}",
        f"@ros2_lv/{domain}/{zid}/0/4/MP/%/%/{name}/%action/{dds(F32)}/{store.hash_rihs01(F32)}/{qos}",
    ]
held = [session.liveliness().declare_token(k) for k in tokens]
print("ready", flush=True)

done = threading.Event()
threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
done.wait(120)
with lock:
    print(
        json.dumps(
            {k: state[k] for k in ("published", "clock_msgs", "obs_msgs")}
        ),
        flush=True,
    )
for h in held:
    h.undeclare()
session.close()
