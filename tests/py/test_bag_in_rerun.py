"""A `--bag` as rerun 0.41 opens it (docs/ros2.md, "Bags: in the rerun viewer"): the bag of a
virtual run read by rerun's own MCAP importer (`rerun.chunk.McapReader`, the code the viewer
runs on `rerun DIR/DIR_0.mcap`, every decoder on, as the viewer has them), in the environment
scripts/test-python.sh makes (`rerun-sdk==0.41.0`).

What it checks is what the docs say a user sees. `/obs` (`sensor_msgs/msg/JointState`, a
type of the importer's `ros2msg` decoder) becomes `Scalars` on /obs/position, /obs/velocity
and /obs/effort, the only entities with rerun's `Scalar` type, so the only ones the viewer's
default layout plots. `/action` (`std_msgs/msg/Float64`) and `/clock`
(`rosgraph_msgs/msg/Clock`) have no such decoder: the `ros2_reflection` decoder keeps each
message whole as one `<type>:message` struct column. It holds every force the run applied
(trace.csv's `action` × 10 N), as float64, and every clock value, which equals the message's
log time (the `message_log_time` timeline). No topic of the bag is missing and nothing is
invented."""

import csv
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

rr = pytest.importorskip("rerun")
pa = pytest.importorskip("pyarrow")

# The `ratelab` command the wheel installed, beside this interpreter.
COMMAND = Path(sys.executable).parent / "ratelab"
# The viewer version the docs describe.
RERUN = "0.41.0"


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def bag_of_a_run(tmp_path):
    """A 1 s virtual run's bag and its trace.csv rows. No router is needed to write a bag:
    the session is not checked for one, and the endpoint it is pointed at has nobody."""
    bag, out = tmp_path / "bag", tmp_path / "out"
    env = {k: v for k, v in os.environ.items()
           if k not in ("ROS_DOMAIN_ID", "ZENOH_ROUTER_CHECK_ATTEMPTS", "ZENOH_CONFIG_OVERRIDE")}
    env["ZENOH_ROUTER_CHECK_ATTEMPTS"] = "-1"
    env["ZENOH_CONFIG_OVERRIDE"] = f'connect/endpoints=["tcp/127.0.0.1:{free_port()}"]'
    done = subprocess.run(
        [str(COMMAND), "run", "--clock", "virtual", "--duration", "1", "--ros2",
         "--bag", str(bag), "--out", str(out)],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    with open(out / "trace.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return bag / "bag_0.mcap", rows


def imported(mcap):
    """What rerun's importer makes of `mcap`: by entity, its temporal columns (name → Arrow
    field) and their values, rows in log-time order, over all its chunks."""
    from rerun.chunk import McapReader

    entities = {}
    for chunk in McapReader(mcap).stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        e = entities.setdefault(chunk.entity_path, {"fields": {}, "rows": []})
        fields = {f.name: f for f in batch.schema if f.name != "rerun.controls.RowId"}
        e["fields"].update(fields)
        columns = {}
        for name, field in fields.items():
            column = batch.column(name)
            if pa.types.is_timestamp(field.type):
                column = column.cast(pa.int64())
            columns[name] = column.to_pylist()
        e["rows"] += [dict(zip(columns, values)) for values in zip(*columns.values())]
    for e in entities.values():
        e["rows"].sort(key=lambda r: r["message_log_time"])
    return entities


def component_type(field):
    return (field.metadata or {}).get(b"rerun:component_type", b"").decode()


def test_the_bag_in_rerun_0_41_plots_obs_and_keeps_action_and_clock_as_decoded_fields(tmp_path):
    assert rr.__version__ == RERUN, (
        f"docs/ros2.md describes rerun {RERUN}'s MCAP importer; this is {rr.__version__} "
        "(scripts/test-python.sh pins the one the docs describe)")
    mcap, rows = bag_of_a_run(tmp_path)
    got = imported(mcap)
    run_times = [int(r["t_ns"]) for r in rows]
    assert len(run_times) == 51

    # The topics with messages, and nothing else (/rosout has none in this run: no node logs).
    assert set(got) == {"/obs", "/obs/position", "/obs/velocity", "/obs/effort", "/action",
                        "/clock", "/parameter_events"}, sorted(got)

    # What the default layout plots: the entities holding rerun's Scalar type, /obs's.
    scalars = {path for path, e in got.items()
               if any(component_type(f) == "rerun.components.Scalar" for f in e["fields"].values())}
    assert scalars == {"/obs/position", "/obs/velocity", "/obs/effort"}
    position = got["/obs/position"]["rows"]
    assert [r["message_log_time"] for r in position] == run_times
    assert all(r["SeriesLines:names"] == ["slider", "hinge"] and len(r["Scalars:scalars"]) == 2
               for r in position), position[:2]

    # /action: one struct column of the message, as the ros2_reflection decoder writes it, on
    # the MCAP log and publish times only (a Float64 has no header stamp). Its `data` is each
    # force applied, in newtons, message i at step i's run time.
    action = got["/action"]
    assert set(action["fields"]) == {"message_log_time", "message_publish_time",
                                     "std_msgs.msg.Float64:message"}
    message = action["fields"]["std_msgs.msg.Float64:message"]
    assert message.type == pa.list_(pa.struct([pa.field("data", pa.float64(), nullable=False)]))
    assert component_type(message) == ""
    assert [r["message_log_time"] for r in action["rows"]] == run_times
    forces = [r["std_msgs.msg.Float64:message"] for r in action["rows"]]
    assert forces == [[{"data": float(r["action"]) * 10.0}] for r in rows]

    # /clock: the same, its `clock` the run time, which is also each message's log time: the
    # viewer's time bar (message_log_time) is the run's clock.
    clock = got["/clock"]
    assert set(clock["fields"]) == {"message_log_time", "message_publish_time",
                                    "rosgraph_msgs.msg.Clock:message"}
    message = clock["fields"]["rosgraph_msgs.msg.Clock:message"]
    assert message.type == pa.list_(pa.struct([pa.field("clock", pa.struct([
        pa.field("sec", pa.int32(), nullable=False),
        pa.field("nanosec", pa.uint32(), nullable=False)]), nullable=False)]))
    assert component_type(message) == ""
    values = [r["rosgraph_msgs.msg.Clock:message"] for r in clock["rows"]]
    assert all(len(v) == 1 for v in values), values[:2]
    clock_ns = [v[0]["clock"]["sec"] * 10**9 + v[0]["clock"]["nanosec"] for v in values]
    assert clock_ns == [r["message_log_time"] for r in clock["rows"]] == run_times
