"""Checks ratelab's Python message classes (src/python/support.py: State, Position, Force,
Image) against ROS 2's types as `rosbags` (an independent implementation) serializes them.

Reads one JSON object on stdin: {"state": HEX, "position": HEX, "force": HEX, "image": HEX},
CDR that ratelab's Rust bridge encoded (src/core/ros_types.rs). Prints one JSON object:
  from_ros: each decoded with rosbags and read with CLASS.from_ros (its fields; bytes as HEX);
  to_ros: HEX of CDR that rosbags serializes from CLASS(...).to_ros() for the values given
          in the input's "values" (state: 5 floats, position: 2, force: 1, image: height,
          width, encoding, step, HEX of the pixels);
  ros_type: each class's ROS_TYPE.
"""

import json
import os
import sys

import numpy as np

from rosbags.typesys import Stores, get_typestore

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "..", "src", "python"))
import support  # noqa: E402  (ratelab's own module, under test)

store = get_typestore(Stores.LATEST)
given = json.load(sys.stdin)
classes = {"state": support.State, "position": support.Position, "force": support.Force,
           "image": support.Image}
out = {"from_ros": {}, "to_ros": {}, "ros_type": {}}
Header = store.types["std_msgs/msg/Header"]
Time = store.types["builtin_interfaces/msg/Time"]
for name, cls in classes.items():
    msg = store.deserialize_cdr(bytes.fromhex(given[name]), cls.ROS_TYPE)
    out["from_ros"][name] = [v.hex() if isinstance(v, bytes) else v
                             for v in cls.from_ros(msg)._fields()]
    out["ros_type"][name] = cls.ROS_TYPE
    values = [bytes.fromhex(v) if name == "image" and i == 4 else v
              for i, v in enumerate(given["values"][name])]
    fields = cls(*values).to_ros()
    Msg = store.types[cls.ROS_TYPE]
    if cls.ROS_TYPE == "sensor_msgs/msg/Image":
        fields = dict(fields, header=Header(stamp=Time(sec=0, nanosec=0), frame_id=""),
                      data=np.frombuffer(fields["data"], dtype=np.uint8))
    if cls.ROS_TYPE == "sensor_msgs/msg/JointState":
        fields = {
            "header": Header(stamp=Time(sec=0, nanosec=0), frame_id=""),
            "name": fields["name"],
            "position": np.array(fields["position"], dtype=np.float64),
            "velocity": np.array(fields["velocity"], dtype=np.float64),
            "effort": np.array(fields["effort"], dtype=np.float64),
        }
    out["to_ros"][name] = bytes(store.serialize_cdr(Msg(**fields), cls.ROS_TYPE)).hex()
# An image cut short, narrower in bytes than in pixels, or with big-endian 16-bit pixels,
# is refused; a mono8 one that says big-endian is read (a byte has no order).
for bad, said in (({"height": 2, "width": 2, "encoding": "mono8", "is_bigendian": 0,
                    "step": 2, "data": b"abc"}, "3 bytes, not step"),
                  ({"height": 1, "width": 4, "encoding": "mono8", "is_bigendian": 0,
                    "step": 2, "data": b"ab"}, "less than its width"),
                  ({"height": 1, "width": 1, "encoding": "mono16", "is_bigendian": 1,
                    "step": 2, "data": b"ab"}, "mono16 with big-endian")):
    try:
        support.Image.from_ros(bad)
        raise SystemExit(f"{bad} was accepted")
    except ValueError as e:
        assert said in str(e), e
assert support.Image.from_ros({"height": 1, "width": 2, "encoding": "mono8", "is_bigendian": 1,
                               "step": 2, "data": b"ab"}).data == b"ab"
# A dict works as a message too, and a JointState with other joints is refused.
assert support.Force.from_ros({"data": 2.5}).newtons == 2.5
try:
    support.Position.from_ros({"name": ["a", "b"], "position": [0, 0], "velocity": []})
    raise SystemExit("other joints were accepted")
except ValueError as e:
    assert "not ['slider', 'hinge']" in str(e), e
print(json.dumps(out))
