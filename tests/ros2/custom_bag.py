"""A rosbag2 bag (MCAP storage) of a type ratelab has no description of, for `ratelab ros2
bag echo` to decode from the ros2msg schema the bag carries (tests/it/ros2_cli.rs). Nothing
here comes from ratelab: the types are registered in rosbags' type store from their .msg
text (`get_types_from_msg`), each message is serialized to CDR by rosbags, and the bag is
written by rosbags' rosbag2 Writer (MCAP storage, metadata.yaml version 9 with the type's
RIHS01 hash from rosbags' `hash_rihs01`).

The channel's schema is the text rosbag2 writes for a type: the type's .msg file (comments
and constants included), then each type it uses after a line of 80 `=` and `MSG: pkg/Type`.

Usage: custom_bag.py DIR   (DIR must not exist yet)
Writes two messages of my_pkg/msg/Reading on /reading, at 1.0 s and 1.5 s, and prints JSON:
{"type": ..., "hash": its RIHS01 hash, "schema": the schema text written}.
"""

import json
import sys

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

READING_MSG = """\
# A made-up reading: ratelab has no description of this type.
uint8 KIND_RAW=0      # constants are not fields
uint8 KIND_FILTERED=1

float64 x             # metres
string label
int32[] counts
geometry_msgs/Vector3 v
Part[<=4] parts       # a name without a package: my_pkg's
bool[2] flags
string<=8 tag "none"
uint8 kind
"""

PART_MSG = """\
# One part of a reading.
string name
float32 w
"""

VECTOR3_MSG = """\
# This represents a vector in free space.

# This is semantically different than a point.
# A vector is always anchored at the origin.
# When a transform is applied to a vector, only the rotational component is applied.

float64 x
float64 y
float64 z
"""

SEPARATOR = "=" * 80


def schema_text():
    """The ros2msg schema rosbag2 writes for my_pkg/msg/Reading."""
    return (
        READING_MSG
        + f"{SEPARATOR}\nMSG: geometry_msgs/Vector3\n"
        + VECTOR3_MSG
        + f"{SEPARATOR}\nMSG: my_pkg/Part\n"
        + PART_MSG
    )


def main():
    out = sys.argv[1]
    store = get_typestore(Stores.LATEST)
    types = {}
    types.update(get_types_from_msg(PART_MSG, "my_pkg/msg/Part"))
    types.update(get_types_from_msg(READING_MSG, "my_pkg/msg/Reading"))
    store.register(types)
    Reading = store.types["my_pkg/msg/Reading"]
    Part = store.types["my_pkg/msg/Part"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    messages = [
        Reading(
            x=1.5,
            label="first",
            counts=np.array([1, -2, 3], dtype=np.int32),
            v=Vector3(x=0.25, y=-0.5, z=1e-05),
            parts=[Part(name="a", w=0.5), Part(name="b c", w=-2.0)],
            flags=np.array([True, False], dtype=np.bool_),
            tag="none",
            kind=1,
        ),
        Reading(
            x=-0.0,
            label="true",
            counts=np.array([], dtype=np.int32),
            v=Vector3(x=0.0, y=0.0, z=100.0),
            parts=[],
            flags=np.array([False, True], dtype=np.bool_),
            tag="",
            kind=0,
        ),
    ]
    name = "my_pkg/msg/Reading"
    rihs01 = store.hash_rihs01(name)
    text = schema_text()
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        c = w.add_connection("/reading", name, msgdef=text, rihs01=rihs01)
        for i, msg in enumerate(messages):
            w.write(c, 1_000_000_000 + i * 500_000_000, store.serialize_cdr(msg, name))
    print(json.dumps({"type": name, "hash": rihs01, "schema": text}))


if __name__ == "__main__":
    main()
