"""The Python package, installed from its wheel into a fresh virtual environment
(scripts/test-python.sh): `ratelab.run` against the command line and the reference runs,
a callable brain against the same brain from a file, errors as exceptions naming Python's
parameters, keywords, NumPy values, the defaults (`ratelab run`'s), Ctrl-C, and the
installed `ratelab` command. A run that must be deterministic says `clock="virtual"`: the
default clock is the real one, as `ratelab run`'s."""

import _thread
import importlib.util
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import traceback
import time
from pathlib import Path

import numpy as np
import pytest

import ratelab

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT.parent / "shared" / "fixtures" / "reference-runs"
# The `ratelab` command the wheel installed, beside this interpreter.
COMMAND = Path(sys.executable).parent / "ratelab"


@pytest.fixture(autouse=True)
def at_the_root(monkeypatch):
    # Graph files and brains are named relative to the repository, as commands.txt does.
    monkeypatch.chdir(ROOT)


def reference(name):
    """The reference run `name`'s flags (commands.txt) and its folder."""
    for line in (REFERENCE / "commands.txt").read_text().splitlines():
        key, _, command = line.partition("|")
        if key == name:
            return command.split()[1:], REFERENCE / name
    raise KeyError(name)


# Three of the chapter's configurations, and a graph with a Python node (which runs in this
# interpreter); the reference runs are the virtual clock's (commands.txt).
CASES = {
    "default": {"clock": "virtual"},
    "control5": {"clock": "virtual", "control_hz": 5},
    "control10-depth100-seed2": {"clock": "virtual", "seed": 2, "control_hz": 10,
                                 "queue_depth": 100},
    "python": {"clock": "virtual", "graph": "graphs/cartpole-python.toml"},
}

#: The deterministic clock, for runs whose figures a test compares.
VIRTUAL = {"clock": "virtual"}


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_run_is_the_reference_run_byte_for_byte(name):
    if not REFERENCE.is_dir():
        pytest.skip("../shared/fixtures/reference-runs is not beside the repository")
    _, folder = reference(name)
    run = ratelab.run(**CASES[name])
    # A Python node's script is named by its absolute path: `<checkout>` in the fixtures.
    metrics = run.metrics_json.replace(str(ROOT.resolve()), "<checkout>")
    assert metrics == (folder / "metrics.json").read_text()
    assert run.trace_csv == (folder / "trace.csv").read_text()


@pytest.mark.parametrize("name", ["default", "control5", "control10-depth100-seed2"])
def test_a_run_equals_the_command_line_s_in_every_figure(name, tmp_path):
    flags, _ = reference(name)
    out = tmp_path / "out"
    subprocess.run([str(COMMAND), "run", *flags, "--out", str(out)], check=True,
                   capture_output=True, timeout=120)
    run = ratelab.run(**CASES[name])
    assert run.metrics_json == (out / "metrics.json").read_text()
    assert run.trace_csv == (out / "trace.csv").read_text()
    assert "\n".join(run.log) == (out / "log.txt").read_text().rstrip("\n")
    # The trace's columns as arrays, units in their names.
    steps = run.metrics["steps"]
    assert len(run.trace["pole_angle_rad"]) == steps
    assert run.trace["pole_angle_rad"].dtype == np.float64
    assert run.trace["fell"].dtype == bool
    assert run.trace["fell"].any() == (not run.metrics["balanced"])
    assert run.trace["latency_ns"].dtype == np.float64


def test_an_estimator_s_error_and_lag_are_the_command_line_s(tmp_path):
    graph = str(ROOT / "graphs" / "cartpole-estimator.toml")
    out = tmp_path / "out"
    subprocess.run([str(COMMAND), "run", "--clock", "virtual", "--graph", graph, "--duration",
                    "5", "--out", str(out)], check=True, capture_output=True, timeout=120)
    run = ratelab.run(graph=graph, duration_s=5, **VIRTUAL)
    assert run.estimator == json.loads((out / "estimator.json").read_text())
    assert run.estimator["topic"] == "/state" and run.estimator["estimator"] == "estimator"
    # Every step but the first (the first estimate is out 1 ms after t = 0).
    assert run.estimator["samples"] == run.metrics["steps"] - 1
    # The low-pass at 20 Hz lags the angular velocity by about 1/(2π·20) s = 8 ms.
    assert 4 <= run.estimator["pole_angvel_lag_ms"] <= 12
    assert any(line.startswith("estimate on /state vs the plant") for line in run.summary)
    assert ratelab.run(duration_s=1, **VIRTUAL).estimator is None


def test_the_rate_cliff_is_the_chapter_s():
    assert ratelab.run(**VIRTUAL).metrics["balanced"]
    fell = ratelab.run(control_hz=5, **VIRTUAL)
    assert not fell.metrics["balanced"]
    assert 0 < fell.metrics["fell_at_s"] < 2.0
    deep = ratelab.run(control_hz=10, queue_depth=100, seed=2, **VIRTUAL)
    assert deep.metrics["queue_depth"] == 100


def load_brain():
    spec = importlib.util.spec_from_file_location("scripted_brain", ROOT / "graphs/brains/scripted.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.act


def test_a_callable_brain_equals_the_same_brain_from_a_file():
    from_file = ratelab.run(policy="graphs/brains/scripted.py", control_hz=10, **VIRTUAL)
    from_here = ratelab.run(policy=load_brain(), control_hz=10, **VIRTUAL)
    assert from_here.trace_csv == from_file.trace_csv
    a, b = dict(from_file.metrics), dict(from_here.metrics)
    assert a.pop("policy").endswith("scripted.py:act")
    assert b.pop("policy").endswith("scripted.py:act")
    assert a == b


def test_a_brain_defined_here_runs_here_and_its_prints_go_to_the_log(capsys):
    calls = []

    def act(obs):
        calls.append(obs.shape)
        if len(calls) == 1:
            print("first observation", obs.dtype)
        return 0.0

    run = ratelab.run(policy=act, duration_s=1.0, **VIRTUAL)
    assert calls and calls[0] == (5,)
    assert any("first observation float32" in line for line in run.log), run.log
    # Nothing was written over the caller's own output, which is its own again.
    print("after")
    assert "after" in capsys.readouterr().out


def test_bad_input_is_an_exception_with_the_one_line():
    with pytest.raises(ValueError) as e:
        ratelab.run(control_hz=-1)
    assert "\n" not in str(e.value) and "control_hz" in str(e.value)
    assert isinstance(e.value, ratelab.SettingError) and isinstance(e.value, ratelab.Error)
    with pytest.raises(ValueError):
        ratelab.run(clock="sundial")
    with pytest.raises(TypeError) as e:
        ratelab.run(duration_s="ten")
    assert "duration_s" in str(e.value) and " s," in str(e.value), str(e.value)
    assert isinstance(e.value, ratelab.SettingTypeError) and isinstance(e.value, ratelab.Error)
    with pytest.raises(FileNotFoundError) as e:
        ratelab.run(graph="graphs/no-such-graph.toml")
    assert "no-such-graph.toml" in str(e.value)
    with pytest.raises(FileNotFoundError):
        ratelab.run(policy="no-such-checkpoint.pt")
    # A brain's script that is not there is a missing file too, as a checkpoint is.
    with pytest.raises(FileNotFoundError) as e:
        ratelab.run(policy="no-such-brain.py", **VIRTUAL)
    assert str(e.value) == "policy file not found: no-such-brain.py", str(e.value)


def test_a_trace_too_large_to_hold_is_refused_before_the_run():
    # Ten years of run time: its trace would be 15.8 G steps; run, it would never end.
    started = time.monotonic()
    with pytest.raises(ratelab.TraceTooLarge) as e:
        ratelab.run(duration_s=315360000.0, **VIRTUAL)
    assert time.monotonic() - started < 10.0
    assert isinstance(e.value, MemoryError) and isinstance(e.value, ratelab.Error)
    line = str(e.value)
    assert "\n" not in line and "MAX_HELD_TRACE_VALUES" in line, line
    assert "(trace_every=2820)" in line and "--trace-every" not in line, line
    # Thinned as asked: steps 1, 11, ..., 101; the metrics count every step.
    run = ratelab.run(duration_s=2.0, trace_every=10, **VIRTUAL)
    assert [int(s) for s in run.trace["step"]] == list(range(1, 102, 10))
    assert run.metrics["steps"] == 101


def test_an_output_is_not_replaced_without_force(tmp_path):
    ratelab.run(duration_s=0.5, out=tmp_path, **VIRTUAL)
    with pytest.raises(FileExistsError) as e:
        ratelab.run(duration_s=0.5, out=tmp_path, **VIRTUAL)
    # The Python parameter, not the command line's flag.
    assert "force" in str(e.value) and "--force" not in str(e.value), str(e.value)
    ratelab.run(duration_s=0.5, out=tmp_path, force=True, **VIRTUAL)


def test_an_output_folder_that_takes_no_files_is_the_system_s_refusal_before_the_run():
    # /proc takes no files, whoever runs this: an OSError, as a recording there is, and
    # before the run (a long run's figures were lost after it).
    started = time.monotonic()
    for kw in [{"out": "/proc"}, {"record": "/proc/ratelab-run.rrd"}]:
        with pytest.raises(OSError) as e:
            # A run of minutes, were it to go ahead.
            ratelab.run(duration_s=100000.0, trace_every=10000, **kw, **VIRTUAL)
        assert not isinstance(e.value, ratelab.SettingError), (kw, e.value)
        assert "/proc" in str(e.value) and "\n" not in str(e.value), str(e.value)
    assert time.monotonic() - started < 30.0, "the runs went ahead"


def test_a_fault_after_the_run_s_end_warns_in_python_s_words_and_is_not_summed_up():
    with pytest.warns(RuntimeWarning) as said:
        run = ratelab.run(duration_s=0.5, kill={"policy": 30.0}, **VIRTUAL)
    assert [str(w.message) for w in said] == [
        "the kill of 'policy' at 30 s starts after the run ends (0.5 s): it does nothing"
    ]
    assert said[0].filename == __file__, "said at the caller's line"
    assert not any(line.startswith("liveliness:") for line in run.summary), run.summary


def test_a_recording_or_out_folder_refused_names_the_keyword_and_raises_its_kind(tmp_path):
    existing = tmp_path / "r.rrd"
    existing.write_bytes(b"not ours")
    with pytest.raises(FileExistsError) as e:
        ratelab.run(duration_s=0.2, record=existing, **VIRTUAL)
    line = str(e.value)
    assert line.startswith("record: ") and "force=True" in line, line
    assert "--record" not in line and "--force" not in line, line
    assert existing.read_bytes() == b"not ours", "never overwritten"
    with pytest.raises(IsADirectoryError) as e:
        ratelab.run(duration_s=0.2, record=tmp_path, **VIRTUAL)
    assert str(e.value).startswith("record: ") and "--record" not in str(e.value), str(e.value)
    blocker = tmp_path / "a-file"
    blocker.write_bytes(b"")
    with pytest.raises(NotADirectoryError) as e:
        ratelab.run(duration_s=0.2, out=blocker / "sub", **VIRTUAL)
    assert "cannot create out folder" in str(e.value), str(e.value)
    assert "--out" not in str(e.value), str(e.value)
    # The OS's reason as Python's own kind of OSError (it was a plain OSError): /proc has
    # no such file to make; a folder given as the policy is a folder.
    with pytest.raises(FileNotFoundError) as e:
        ratelab.run(duration_s=0.2, out="/proc", **VIRTUAL)
    assert "/proc/" in str(e.value) and "--out" not in str(e.value), str(e.value)
    with pytest.raises(IsADirectoryError) as e:
        ratelab.run(duration_s=0.2, policy=tmp_path, **VIRTUAL)
    assert str(tmp_path) in str(e.value), str(e.value)
    # A recording that cannot be made says its kind too (it was a plain OSError).
    with pytest.raises(FileNotFoundError) as e:
        ratelab.run(duration_s=0.2, record="/proc/ratelab/x.rrd", **VIRTUAL)
    assert str(e.value).startswith("record: cannot write /proc/ratelab/x.rrd"), str(e.value)
    with pytest.raises(NotADirectoryError) as e:
        ratelab.run(duration_s=0.2, record=blocker / "x.rrd", **VIRTUAL)
    assert str(e.value).startswith("record: ") and "--record" not in str(e.value), str(e.value)
    # An empty path names nothing: the setting's mistake (it was FileNotFoundError).
    for keyword in ("policy", "record", "out", "graph"):
        with pytest.raises(ratelab.SettingError) as e:
            ratelab.run(duration_s=0.2, **{keyword: ""}, **VIRTUAL)
        assert isinstance(e.value, ValueError), keyword
        assert str(e.value) == f"{keyword} is an empty path: it names no file or folder"


def test_a_brain_that_raises_fails_its_node_and_keeps_the_figures():
    ticks = []

    def act(obs):
        ticks.append(obs)
        if len(ticks) == 10:
            raise RuntimeError("too far right")
        return 0.5

    with pytest.raises(ratelab.NodeFailed) as e:
        ratelab.run(policy=act, **VIRTUAL)
    assert isinstance(e.value, RuntimeError) and isinstance(e.value, ratelab.Error)
    assert "too far right" in str(e.value) and "policy" in str(e.value)
    assert e.value.run.metrics["balanced"] is False
    assert e.value.run.metrics["steps"] > 0
    # The brain's own exception is the cause, its traceback reaching into `act`.
    cause = e.value.__cause__
    assert isinstance(cause, RuntimeError) and str(cause) == "too far right", repr(cause)
    frames = traceback.extract_tb(cause.__traceback__)
    assert frames and frames[-1].name == "act", frames
    assert frames[-1].filename == __file__, frames
    # It starts at the learner's line: no frame of ratelab's wrapper that called `act`.
    assert [f.name for f in frames] == ["act"], frames


def test_a_brain_or_node_class_that_cannot_take_its_argument_is_refused_naming_it():
    def act(obs, gain):
        return gain * obs[1]

    with pytest.raises(ratelab.SettingTypeError) as e:
        ratelab.run(policy=act, **VIRTUAL)
    line = str(e.value)
    assert line.startswith("policy: a brain is called with one argument"), line
    assert "act(obs, gain) cannot take it" in line and "<ratelab>" not in line, line

    class NoHandle:
        def __init__(self):
            pass

    with pytest.raises(ratelab.SettingTypeError) as e:
        ratelab.run(graph="graphs/cartpole-python.toml", nodes={"policy": NoHandle}, **VIRTUAL)
    line = str(e.value)
    assert line.startswith("nodes['policy']: a node class is made with one argument"), line
    assert "NoHandle() cannot take it" in line, line


def test_refusals_of_faults_and_of_the_chain_speak_in_keywords():
    # Not the command line's `stall polcy@200 ms+100 ms` or `(--rate NODE=HZ, …)`.
    with pytest.raises(ratelab.SettingError) as e:
        ratelab.run(stall={"polcy": (0.2, 0.1)}, **VIRTUAL)
    assert str(e.value).startswith('stall["polcy"]: unknown node \'polcy\' (nodes: '), str(e.value)
    with pytest.raises(ratelab.SettingError) as e:
        ratelab.run(kill={"polic": 0.5}, **VIRTUAL)
    assert str(e.value).startswith('kill["polic"]: unknown node'), str(e.value)
    with pytest.raises(ratelab.SettingError) as e:
        ratelab.run(graph="graphs/cartpole-open-loop.toml", control_hz=10, **VIRTUAL)
    line = str(e.value)
    assert line.startswith("control_hz speaks of the chapter's chain"), line
    assert "rate={'NODE': HZ}, depth={'TOPIC': N}" in line and "--" not in line, line


def test_one_topic_s_depth_set_two_ways_is_refused_naming_both():
    # depth= and qos='depth=' would leave one ignored: neither wins unseen.
    with pytest.raises(ratelab.SettingError) as e:
        ratelab.run(depth={"/obs": 3}, qos={"/obs": {"depth": 5}}, **VIRTUAL)
    line = str(e.value)
    assert line.startswith('depth["/obs"]=3 and qos["/obs"]='), line
    assert line.endswith("both set the history depth of topic '/obs'; give one"), line
    # The same depth both ways says one thing.
    r = ratelab.run(depth={"/obs": 3}, qos={"/obs": "depth=3"}, **VIRTUAL)
    assert r.metrics["topics"]["/obs"]["depth"] == 3, r.metrics["topics"]["/obs"]


def test_a_brain_file_that_fails_to_load_keeps_its_exception_as_the_cause(tmp_path):
    # Its import failing or its `act` unable to take the observation is refused before the
    # run; the file's own exception, with its traceback, is the cause (`except ImportError`
    # on `e.__cause__`, `%debug`), as a failed node's is.
    broken = tmp_path / "broken.py"
    broken.write_text("import notamodule_xyz\n\ndef act(obs):\n    return 0.0\n")
    with pytest.raises(ratelab.SettingError) as e:
        ratelab.run(policy=str(broken), **VIRTUAL)
    assert "ModuleNotFoundError" in str(e.value) and "<ratelab>" not in str(e.value)
    cause = e.value.__cause__
    assert isinstance(cause, ModuleNotFoundError), repr(cause)
    assert any(f.filename == str(broken) for f in traceback.extract_tb(cause.__traceback__))
    two = tmp_path / "two.py"
    two.write_text("def act(obs, extra):\n    return 0.0\n")
    with pytest.raises(ratelab.Error) as e:
        ratelab.run(policy=str(two), **VIRTUAL)
    line = str(e.value)
    assert not isinstance(e.value, ratelab.NodeFailed), line
    assert "act(obs, extra) cannot take it" in line and "<ratelab>" not in line, line
    assert line.startswith(f"{two}:1: "), line


def test_a_node_class_that_raises_is_the_cause_with_its_traceback():
    with pytest.raises(ratelab.NodeFailed) as e:
        ratelab.run(graph="graphs/cartpole-python.toml", nodes={"policy": _RaisingBalancer},
                    duration_s=1.0, **VIRTUAL)
    assert "no good" in str(e.value), str(e.value)
    cause = e.value.__cause__
    assert isinstance(cause, ValueError) and str(cause) == "no good", repr(cause)
    frames = traceback.extract_tb(cause.__traceback__)
    assert any(f.name == "on_obs" and f.filename == __file__ for f in frames), frames
    assert frames[0].filename == __file__, frames


class _RaisingBalancer:
    """A Python node class for the policy that raises on its first observation."""

    def __init__(self, node):
        from ratelab import Force, State

        self.pub = node.create_publisher(Force, "/action", 1)
        node.create_subscription(State, "/obs", self.on_obs, 1)

    def on_obs(self, msg):
        raise ValueError("no good")


def test_ctrl_c_stops_a_run():
    # Python's own Ctrl-C: the signal flag a SIGINT sets, raised in the main thread. A
    # process started in the background by a shell ignores SIGINT, and Python then leaves it
    # so: give it Python's handler, as an interactive interpreter has.
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        timer = threading.Timer(1.0, _thread.interrupt_main)
        timer.start()
        started = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            ratelab.run(clock="real", duration_s=60.0)
        assert time.monotonic() - started < 10.0
        timer.cancel()
    finally:
        signal.signal(signal.SIGINT, before)
    # The interpreter is still good for another run.
    assert ratelab.run(duration_s=0.5, **VIRTUAL).metrics["steps"] == 26  # t = 0, 20, …, 500 ms


def test_ctrl_c_stops_an_exercise():
    # ex3 runs the real clock twice for 5 s; Ctrl-C ends the run in progress, grades nothing.
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        timer = threading.Timer(1.0, _thread.interrupt_main)
        timer.start()
        started = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            ratelab.exercise("ex3", {"matched_obs_drops": 100, "why": "a guess"},
                             dir=ROOT / "exercises")
        assert time.monotonic() - started < 4.0
        timer.cancel()
    finally:
        signal.signal(signal.SIGINT, before)


def test_the_installed_command_and_module():
    smoke = subprocess.run([str(COMMAND), "run", "--smoke"], capture_output=True, text=True,
                           timeout=120)
    assert smoke.returncode == 0, smoke.stderr
    assert "BALANCED" in smoke.stdout
    bad = subprocess.run([str(COMMAND), "run", "--control-hz", "-1"], capture_output=True,
                         text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1, bad.stderr
    imported = subprocess.run([sys.executable, "-c", "import ratelab; print(ratelab.__version__)"],
                              capture_output=True, text=True, timeout=60)
    assert imported.returncode == 0 and imported.stdout.strip() == ratelab.__version__
    # The module comes from the environment, not from the source tree.
    assert "site-packages" in ratelab.__file__


def in_a_fresh_interpreter(code):
    """`code` run by `python -c` in a fresh process of this environment: its stdout."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_a_run_printed_says_what_a_fault_on_the_actuator_did():
    # As the summary says it: the plant stood still meanwhile (it said "balanced" alone).
    stalled = ratelab.run(duration_s=1.0, stall={"actuator": (0.0, 1.0)}, **VIRTUAL)
    assert repr(stalled).startswith(
        "<ratelab.Run balanced while the plant ran (the actuator lost 50 ticks)"
    ), repr(stalled)
    killed = ratelab.run(duration_s=1.0, kill={"actuator": 0.5}, **VIRTUAL)
    assert repr(killed).startswith("<ratelab.Run actuator killed at 0.50 s"), repr(killed)
    # A kill set after the run's end (warned of) did nothing: not said.
    with pytest.warns(RuntimeWarning):
        late = ratelab.run(duration_s=1.0, kill={"actuator": 20.0}, **VIRTUAL)
    assert repr(late).startswith("<ratelab.Run balanced 1.0 s"), repr(late)
    assert repr(ratelab.run(duration_s=1.0, **VIRTUAL)).startswith("<ratelab.Run balanced 1.0 s")


def test_runs_compare_by_what_they_wrote():
    # A learner checks "same seed, same run" with `==` (it raised: the dataclass compared
    # dicts of arrays), and may keep runs in a set.
    a, b = (ratelab.run(clock="virtual", duration_s=0.5, seed=2) for _ in range(2))
    other = ratelab.run(clock="virtual", duration_s=0.5, seed=3)
    assert a == b and not (a != b) and a.trace_csv == b.trace_csv
    assert a != other and len({a, b, other}) == 2
    assert (a == "a run") is False
    assert "Two runs are equal" in ratelab.Run.__doc__ and "trace_csv:" in ratelab.Run.__doc__


def test_first_runs_from_two_threads_at_once_both_finish():
    # The first calls of a fresh process load ratelab's support module; two threads at once
    # deadlocked there (one holding the interpreter while it waited for the other, which
    # needed the interpreter to finish), never to end. Each run as one thread alone.
    said = in_a_fresh_interpreter("\n".join([
        "import faulthandler, sys, threading, ratelab",
        "faulthandler.dump_traceback_later(60, exit=True)",
        "out = {}",
        "def brain(tag):",
        "    def act(obs):",
        "        print(tag)",
        "        return 0.0",
        "    return act",
        "def go(seed):",
        "    out[seed] = ratelab.run(clock='virtual', duration_s=0.5, seed=seed,",
        "                            policy=brain(f'from-{seed}'))",
        "threads = [threading.Thread(target=go, args=(s,)) for s in (0, 1)]",
        "[t.start() for t in threads]; [t.join() for t in threads]",
        "alone = ratelab.run(clock='virtual', duration_s=0.5, seed=1, policy=brain('from-1'))",
        "mine = {s: [l for l in out[s].log if 'from-' in l] for s in (0, 1)}",
        "own = all(mine[s] and all(f'from-{s}' in l for l in mine[s]) for s in (0, 1))",
        "print(len(out), out[1] == alone, own, sys.stdout is sys.__stdout__)",
    ]))
    # Each run's log holds its own brain's lines alone, and stdout is put back after.
    assert said.split() == ["2", "True", "True", "True"], said


def test_a_run_from_inside_a_brain_is_refused_not_waited_for():
    # The outer run holds the process's one run until its brain returns: a nested call
    # waited on it for good. It is refused at once, naming the brain that made it.
    said = in_a_fresh_interpreter("\n".join([
        "import faulthandler, ratelab",
        "faulthandler.dump_traceback_later(60, exit=True)",
        "refused = []",
        "def act(obs):",
        "    if not refused:",
        "        try:",
        "            ratelab.run(clock='virtual', duration_s=0.1)",
        "        except ratelab.RunInProgress as e:",
        "            refused.append(str(e) if isinstance(e, (RuntimeError, ratelab.Error))",
        "                           else 'not a RuntimeError')",
        "    return 0.0",
        "outer = ratelab.run(clock='virtual', duration_s=0.3, policy=act)",
        "print(repr(outer).split()[1]); print(refused[0]); print(outer.metrics['policy'])",
    ]))
    verdict, refusal, label = said.splitlines()
    assert verdict == "balanced", said
    # A function typed where there is no file is named by where it was typed, not by a
    # file name that does not exist (a notebook cell's is a kernel's temporary name).
    assert label == "Python brain act in <string>", said
    assert refusal.startswith(
        "ratelab.run() was called from inside a run (the brain act in <string>): "), said
    assert "start it after the run in progress returns" in refusal, said


def test_a_run_from_a_thread_a_brain_started_and_joins_is_refused_not_waited_for():
    # The brain's thread calls ratelab.run and the brain joins it: the thread waited for the
    # outer run, which waited for the brain, for good. The thread's run is refused (the
    # brain is seen inside Thread.join on it), the join returns, and the outer run goes on.
    # Here the brain joins on a later call than the one that started the thread.
    said = in_a_fresh_interpreter("\n".join([
        "import faulthandler, threading, ratelab",
        "faulthandler.dump_traceback_later(60, exit=True)",
        "said = []",
        "def inner():",
        "    try:",
        "        ratelab.run(clock='virtual', duration_s=0.1)",
        "        said.append('ran')",
        "    except ratelab.RunInProgress as e:",
        "        said.append(str(e))",
        "started = []",
        "def act(obs):",
        "    if not started:",
        "        started.append(threading.Thread(target=inner))",
        "        started[0].start()",
        "    elif started[0].is_alive():",
        "        started[0].join()",
        "    return 0.0",
        "outer = ratelab.run(clock='virtual', duration_s=0.3, policy=act)",
        "print(repr(outer).split()[1]); print(said[0])",
        # Threads that only wait their turn still run one after another.
        "done = []",
        "ts = [threading.Thread(target=lambda: done.append(",
        "      repr(ratelab.run(clock='virtual', duration_s=0.2)).split()[1])) for _ in range(3)]",
        "[t.start() for t in ts]; [t.join() for t in ts]; print(done)",
        # A brain that joins with a timeout goes on by itself: its thread's run waits.
        "later = []",
        "def act2(obs):",
        "    if not later:",
        "        later.append(threading.Thread(target=lambda: later.append(",
        "            repr(ratelab.run(clock='virtual', duration_s=0.1)).split()[1])))",
        "        later[0].start()",
        "    later[0].join(timeout=0.01)",
        "    return 0.0",
        "ratelab.run(clock='virtual', duration_s=0.1, policy=act2); later[0].join()",
        "print(later[1:])",
    ]))
    verdict, refusal, turns, waited = said.splitlines()[-4:]
    assert waited == "['balanced']", said
    assert verdict == "balanced", said
    assert refusal == (
        "ratelab.run() was called from a thread that the brain act in <string> of the run in "
        "progress is joining: that run holds the process's one run until its callback "
        "returns, so neither could go on; start this run after the run in progress returns"
    ), said
    assert turns == "['balanced', 'balanced', 'balanced']", said


def test_a_partial_or_a_callable_object_as_a_brain_is_named_by_what_it_wraps():
    # Neither has a name or code of its own: they were both `act in <callable>`.
    said = in_a_fresh_interpreter("\n".join([
        "import functools, ratelab",
        "def act(obs, gain=1.0): return 0.0",
        "class Brain:",
        "    def __call__(self, obs): return 0.0",
        "for b in (functools.partial(act, gain=2.0), Brain()):",
        "    print(ratelab.run(clock='virtual', duration_s=0.1, policy=b).metrics['policy'])",
    ]))
    assert said.splitlines() == [
        "Python brain partial(act) in <string>",
        "Python brain Brain.__call__ in <string>",
    ], said


def test_import_ratelab_does_not_import_numpy():
    # #76: `import ratelab` costs the package, not NumPy (the command imports it too).
    said = in_a_fresh_interpreter(
        "import sys, ratelab; print('numpy' in sys.modules, 'pandas' in sys.modules)")
    assert said.split() == ["False", "False"], said


def test_a_run_imports_numpy_only_when_its_trace_is_asked_for():
    # #76: a fresh process's `ratelab.run()` costs what `ratelab run` does; NumPy is imported
    # when the trace's arrays are first asked for, and they are the same as ever.
    said = in_a_fresh_interpreter("\n".join([
        "import json, sys, ratelab",
        "run = ratelab.run(clock='virtual', duration_s=1)",
        "repr(run), run._repr_html_(), run.metrics, run.log, run.trace_csv",
        "print(json.dumps({'after_run': 'numpy' in sys.modules}))",
        "trace = run.trace",
        "print(json.dumps({'after_trace': 'numpy' in sys.modules,",
        "                  'cached': run.trace is trace, 'dict': type(trace) is dict,",
        "                  'columns': [[k, v.dtype.str, v.tobytes().hex()]",
        "                              for k, v in trace.items()]}))",
    ]))
    before, after = (json.loads(line) for line in said.splitlines())
    assert before == {"after_run": False}
    assert after["after_trace"] and after["cached"] and after["dict"], after
    here = ratelab.run(clock="virtual", duration_s=1)
    assert after["columns"] == [[k, v.dtype.str, v.tobytes().hex()]
                                for k, v in here.trace.items()]
    # The arrays are trace.csv's text: floats (an empty cell NaN), flags, counts.
    header, *rows = (line.split(",") for line in here.trace_csv.splitlines())
    assert list(here.trace) == [ratelab.TRACE_COLUMNS.get(n, n) for n in header]
    for i, array in enumerate(here.trace.values()):
        cells = [row[i] for row in rows]
        if array.dtype == np.float64:
            text = np.array([float(c) if c else math.nan for c in cells])
        elif array.dtype == bool:
            text = np.array([c == "true" for c in cells])
        else:
            assert array.dtype == np.int64, array.dtype
            text = np.array([int(c) for c in cells], dtype=np.int64)
        assert np.array_equal(array, text, equal_nan=array.dtype == np.float64), header[i]
    assert here.trace["pole_angle_rad"].dtype == np.float64 and len(here.trace["step"]) == 51


def test_a_launch_starts_its_processes_through_this_python(tmp_path):
    # `launch --processes` starts `python -m ratelab process …` for each process.
    done = subprocess.run(
        [str(COMMAND), "launch", "--processes", "--headless", "--listen", "tls/127.0.0.1:0",
         "--clock", "virtual", "--seed", "0", "--graph", "graphs/cartpole-estimator.toml",
         "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stderr
    _, folder = reference("launch-lockstep")
    if REFERENCE.is_dir():
        assert (tmp_path / "metrics.json").read_text() == (folder / "metrics.json").read_text()


def test_a_camera_renders_through_this_python(tmp_path):
    # A camera with `mujoco = 1` starts its renderer as `python -m ratelab render-camera`.
    drawn = ratelab.run(graph="graphs/cartpole-camera.toml", duration_s=3, **VIRTUAL)
    run = ratelab.run(graph="graphs/cartpole-camera-mujoco.toml", duration_s=3, **VIRTUAL)
    cannot = [line for line in run.log if "drawing synthetic frames instead" in line]
    if cannot and os.environ.get("RATELAB_REQUIRE_RENDER") != "1":
        pytest.skip(f"this machine cannot render: {cannot[0]}")
    assert not cannot, cannot
    assert run.metrics["balanced"] and drawn.metrics["balanced"]
    # Rendered frames are another rasterizer's: the estimate from them is not the drawn one.
    assert run.estimator["rms"][2] != drawn.estimator["rms"][2]


def test_the_stubs_are_shipped():
    folder = Path(ratelab.__file__).parent
    assert (folder / "_native.pyi").is_file()
    assert (folder / "py.typed").is_file()


def test_a_sweep_is_the_command_line_s_table(tmp_path):
    table = ratelab.sweep(control_hz=[50, 5], seeds=[0, 1])
    out = tmp_path / "sweep.csv"
    subprocess.run([str(COMMAND), "sweep", "--control-hz", "50,5", "--seeds", "0,1",
                    "--csv", str(out)], check=True, capture_output=True, timeout=120)
    assert table.csv == out.read_text()
    assert len(table) == 4
    by_rate = {(r["control_hz"], r["seed"]): r["balanced"] for r in table}
    assert by_rate[(50, 0)] is True and by_rate[(5, 0)] is False
    frame = pytest.importorskip("pandas") and table.to_pandas()
    assert list(frame["control_hz"]) == table["control_hz"]


def test_a_cliff_is_where_a_run_falls_and_the_next_rate_up_balances():
    table = ratelab.cliff(seeds=[0], min_hz=4, max_hz=12, step_hz=0.5)
    (row,) = table.rows
    assert row["seed"] == 0 and row["runs"] > 0
    falls, balances = row["falls_at_hz"], row["balances_at_hz"]
    assert balances == pytest.approx(falls + 0.5)
    assert not ratelab.run(control_hz=falls, **VIRTUAL).metrics["balanced"]
    assert ratelab.run(control_hz=balances, **VIRTUAL).metrics["balanced"]
    with pytest.raises(ValueError) as e:
        ratelab.cliff(min_hz=20, max_hz=10)
    assert str(e.value) == "min_hz (20) must not be above max_hz (10)"
    assert isinstance(e.value, ratelab.SettingError)


def scripted_act(obs):
    """The built-in scripted balancer (src/runtime/policy.rs, `Scripted`) in Python, the same
    arithmetic in the same order on the same doubles: θ = atan2(sin θ, cos θ),
    u = 10θ + 2·pole_angvel + 0.4·cart_pos + 0.8·cart_vel, clipped to [-1, 1]."""
    theta = math.atan2(float(obs[3]), float(obs[2]))
    u = 10.0 * theta + 2.0 * float(obs[4]) + 0.4 * float(obs[0]) + 0.8 * float(obs[1])
    return min(max(u, -1.0), 1.0)


def without_policy(table):
    """A table's rows without the brain's name (a callable is named by its file and name)."""
    return [{k: v for k, v in row.items() if k != "policy"} for row in table]


def test_a_sweep_takes_a_brain_defined_here():
    grid = dict(control_hz=np.array([5, 10, 50]), seeds=[0, 1], duration_s=2, clock="virtual")
    mine = ratelab.sweep(policy=scripted_act, **grid)
    built_in = ratelab.sweep(policy="scripted", **grid)
    from_file = ratelab.sweep(policy="graphs/brains/scripted.py", **grid)
    assert len(mine) == 6
    # Every figure, to the last bit: the rows' cells are the CSV's text.
    assert without_policy(mine) == without_policy(built_in) == without_policy(from_file)
    assert any(row["fell_at_s"] is not None for row in mine)
    assert all(row["policy"].endswith(":scripted_act") for row in mine), mine.rows[0]


def test_a_callable_brain_equals_a_brain_file_in_a_sweep(tmp_path):
    brain = tmp_path / "zero.py"
    brain.write_text("def act(obs):\n    return 0.0\n")
    grid = dict(control_hz=np.array([10, 50]), seeds=[0], duration_s=1, clock="virtual")
    mine = ratelab.sweep(policy=lambda obs: 0.0, **grid)
    from_file = ratelab.sweep(policy=str(brain), **grid)
    assert len(mine) == 2
    assert without_policy(mine) == without_policy(from_file)
    assert mine.rows[0]["policy"].endswith(":<lambda>"), mine.rows[0]


def test_a_cliff_takes_a_brain_defined_here():
    search = dict(seeds=[0], min_hz=4, max_hz=12, step_hz=0.5)
    assert ratelab.cliff(policy=scripted_act, **search).csv == ratelab.cliff(**search).csv


def test_a_brain_that_raises_in_a_sweep_fails_its_runs():
    def act(obs):
        raise RuntimeError("not today")

    with pytest.raises(ratelab.NodeFailed) as e:
        ratelab.sweep(policy=act, control_hz=[50, 10], seeds=[0], duration_s=1)
    assert "2 of 2 runs failed a node" in str(e.value) and "not today" in str(e.value)
    assert e.value.run is None
    with pytest.raises(ValueError) as e:
        ratelab.cliff(policy=act, seeds=[0], min_hz=4, max_hz=12, step_hz=0.5)
    assert "not today" in str(e.value) and "seed 0" in str(e.value)


@pytest.mark.parametrize("call, name", [
    (lambda: ratelab.sweep(seeds=[]), "seeds"),
    (lambda: ratelab.sweep(control_hz=np.array([])), "control_hz"),
    (lambda: ratelab.sweep(clock=[]), "clock"),
    (lambda: ratelab.sweep(control_hz=[10, 0]), "control_hz"),
    (lambda: ratelab.sweep(queue_depth=[0]), "queue_depth"),
    (lambda: ratelab.sweep(control_hz=[50] * 3000, sensor_hz=[50] * 3000), "control_hz"),
    (lambda: ratelab.sweep(duration_s=0), "duration_s"),
    (lambda: ratelab.sweep(clock=["virtual", "sundial"]), "clock"),
    (lambda: ratelab.sweep(rate={"policy": 20}), "rate"),
    (lambda: ratelab.cliff(seeds=[]), "seeds"),
    (lambda: ratelab.cliff(step_hz=0), "step_hz"),
    (lambda: ratelab.cliff(step_hz=0.0001), "step_hz"),
    (lambda: ratelab.cliff(max_hz=np.inf), "max_hz"),
], ids=lambda x: x if isinstance(x, str) else None)
def test_a_sweep_s_and_a_cliff_s_errors_name_python_parameters(call, name):
    with pytest.raises(ValueError) as e:
        call()
    line = str(e.value)
    assert line.startswith(name) or f" {name}" in line, line
    assert "\n" not in line and not FLAG.search(line), line
    assert isinstance(e.value, ratelab.SettingError)
    if name == "seeds":
        assert line.startswith("seeds: an empty list runs nothing"), line


def exercises_copy(tmp_path, **predictions):
    """The exercises folder (and the graphs beside it) copied to `tmp_path`, every prediction
    emptied, then those given
    (`ex1='fails_at_hz = 5'`) written with a `why`."""
    folder = tmp_path / "exercises"
    shutil.copytree(ROOT / "exercises", folder)
    # The graphs some exercises run on, named from the exercises folder as `../graphs/…`.
    shutil.copytree(ROOT / "graphs", tmp_path / "graphs")
    for e in ratelab.exercises():
        path = folder / e["file"]
        text = path.read_text()
        head = text[: re.search(r"^\[prediction\]", text, re.M).start()]
        given = predictions.get(e["id"])
        body = f'{given}\nwhy = "a guess"\n' if given else 'why = ""\n'
        path.write_text(head + "[prediction]\n" + body)
    return folder


def test_the_learners_pytest_of_predictions_passes_a_right_one_and_fails_a_wrong_one(tmp_path):
    """`python -m pytest exercises/` (exercises/test_predictions.py) as a learner runs it:
    ex1 predicted right passes, the others unpredicted are skipped; predicted wrong, its test
    fails with the prediction beside the outcome."""

    def pytest_of(prediction):
        folder = exercises_copy(tmp_path / prediction.replace(" ", ""), ex1=prediction)
        return subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
             str(folder / "test_predictions.py")],
            capture_output=True, text=True, cwd=folder, timeout=600,
        )

    right = pytest_of("fails_at_hz = 5")
    assert right.returncode == 0, right.stdout + right.stderr
    assert "1 passed" in right.stdout and "skipped" in right.stdout, right.stdout
    wrong = pytest_of("fails_at_hz = 50")
    assert wrong.returncode == 1, wrong.stdout + wrong.stderr
    assert "1 failed" in wrong.stdout, wrong.stdout
    assert "ex1 is not passed" in wrong.stdout, wrong.stdout
    assert ("fails_at_hz (missed): You predicted the pole first fails at 50 Hz; "
            "it first fell at 5 Hz.") in wrong.stdout, wrong.stdout


def test_copy_exercises_gives_a_folder_that_runs_and_is_never_overwritten_unasked(tmp_path):
    folder = ratelab.copy_exercises(tmp_path / "lab")
    assert folder == str(tmp_path / "lab" / "exercises")
    shown = lambda d: sorted(n for n in os.listdir(d) if not n.startswith((".", "__")))
    assert shown(folder) == shown(ROOT / "exercises")
    assert shown(tmp_path / "lab" / "graphs") == shown(ROOT / "graphs")
    found = ratelab.exercise("ex1", {"fails_at_hz": 5, "why": "too slow to catch it"}, dir=folder)
    assert found.passed, found.report
    # ex6 runs on a graph named from the exercises folder as ../graphs/…: there too.
    mine = Path(folder) / "ex6_my_limiter.py"
    assert mine.read_text() == (ROOT / "exercises" / "ex6_my_limiter.py").read_text()
    mine.write_text("# my own node, half written\n")
    with pytest.raises(FileExistsError) as e:
        ratelab.copy_exercises(tmp_path / "lab")
    assert "force=True" in str(e.value) and "exercises" in str(e.value)
    assert mine.read_text() == "# my own node, half written\n", "nothing copied"
    assert ratelab.copy_exercises(tmp_path / "lab", force=True) == folder
    assert mine.read_text() == (ROOT / "exercises" / "ex6_my_limiter.py").read_text()
    with pytest.raises(ratelab.SettingTypeError):
        ratelab.copy_exercises(5)


def test_an_exercise_returns_its_checks(tmp_path):
    folder = exercises_copy(tmp_path)
    found = ratelab.exercise("ex1", {"fails_at_hz": 5, "why": "too slow to catch it"}, dir=folder)
    assert found.passed and found.not_passed == 0
    assert found.checks and all(c.passed for c in found.checks)
    assert any("5 Hz" in line for line in found.reconcile), found.reconcile
    assert [(p.key, p.verdict) for p in found.predictions] == [("fails_at_hz", "right")]
    assert found.predictions[0].said.endswith(": right.") and not found.missed
    assert any(line.startswith("== ex1") for line in found.report)
    # A prediction that misses is not passed (the command exits 1), checks all held.
    wrong = ratelab.exercise("ex1", {"fails_at_hz": 50, "why": "a guess"}, dir=folder)
    assert not wrong.passed and wrong.not_passed == 1 and not wrong.failed_checks
    assert [(p.key, p.verdict) for p in wrong.missed] == [("fails_at_hz", "missed")]
    said = "You predicted the pole first fails at 50 Hz; it first fell at 5 Hz."
    assert wrong.reconcile == [said] and wrong.missed[0].said == said
    # A prediction of the wrong type is not passed; none at all is refused.
    bad = ratelab.exercise("ex1", {"fails_at_hz": "five", "why": "?"}, dir=folder)
    assert not bad.passed and bad.not_passed >= 1
    assert [p.verdict for p in bad.missed] == ["unreadable"]
    with pytest.raises(ratelab.NoPrediction) as e:
        ratelab.exercise("ex1", dir=folder)
    assert "ex1_rate_cliff.toml" in str(e.value)
    # One hierarchy: ratelab's own Error, and Python's ValueError, named where it is public.
    assert isinstance(e.value, ratelab.Error) and isinstance(e.value, ValueError)
    assert type(e.value).__module__ == "ratelab", type(e.value).__module__
    with pytest.raises(ValueError):
        ratelab.exercise("ex99", {"why": "?"}, dir=folder)
    # No folder: said as the folder, with the keyword to give it.
    with pytest.raises(FileNotFoundError) as e:
        ratelab.exercise("ex1", {"fails_at_hz": 5, "why": "slow"}, dir=tmp_path / "none")
    assert "give the folder with dir=FOLDER" in str(e.value), str(e.value)
    # A prediction given here is judged here: the keyword named, never the learner's file.
    for given, line in [
        ({"fails_at_hz": 5}, "prediction: missing why (ex1 asks for fails_at_hz and why)"),
        ({"fail_at_hz": 5, "why": "slow"},
         "prediction: 'fail_at_hz' is not a key of ex1's prediction (fails_at_hz and why)"),
        ({"fails_at_hz": 5, "why": "slow", "extra": 1},
         "prediction: 'extra' is not a key of ex1's prediction (fails_at_hz and why)"),
    ]:
        with pytest.raises(ratelab.SettingError) as e:
            ratelab.exercise("ex1", given, dir=folder)
        assert str(e.value) == line, str(e.value)
        assert not isinstance(e.value, ratelab.NoPrediction)


def test_the_exercises_run_as_pytest_tests_on_the_learner_s_predictions(tmp_path):
    def pytest_on(folder):
        return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                               str(folder)], capture_output=True, text=True, timeout=300)

    done = pytest_on(exercises_copy(tmp_path / "a", ex1="fails_at_hz = 5"))
    assert done.returncode == 0, done.stdout
    assert "1 passed" in done.stdout and "skipped" in done.stdout
    unreadable = pytest_on(exercises_copy(tmp_path / "b", ex1='fails_at_hz = "five"'))
    assert unreadable.returncode == 1, unreadable.stdout
    assert "test_exercise[ex1]" in unreadable.stdout
    # A prediction that missed fails its test, the prediction beside the outcome.
    missed = pytest_on(exercises_copy(tmp_path / "c", ex1="fails_at_hz = 50"))
    assert missed.returncode == 1, missed.stdout
    assert "test_exercise[ex1]" in missed.stdout
    assert ("fails_at_hz (missed): You predicted the pole first fails at 50 Hz; it first fell "
            "at 5 Hz.") in missed.stdout, missed.stdout


def test_a_node_class_given_here_runs_as_the_same_class_from_its_file():
    # The class imported from its file, given for the graph's Python node: the reference run.
    spec = importlib.util.spec_from_file_location(
        "my_balancer", ROOT / "graphs/nodes/scripted_balancer.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    from_file = ratelab.run(graph="graphs/cartpole-python.toml", **VIRTUAL)
    given = ratelab.run(graph="graphs/cartpole-python.toml",
                        nodes={"policy": module.ScriptedBalancer}, **VIRTUAL)
    assert given.trace_csv == from_file.trace_csv
    assert given.metrics_json == from_file.metrics_json
    # `import ratelab` is still the package after Python nodes ran (their message classes
    # joined it).
    assert sys.modules["ratelab"] is ratelab and ratelab.Force(newtons=1.0).newtons == 1.0
    with pytest.raises(TypeError):
        ratelab.run(graph="graphs/cartpole-python.toml", nodes={"policy": "ScriptedBalancer"})


def test_a_node_class_defined_in_a_cell_runs_here():
    from ratelab import Force, State

    class Hold:
        def __init__(self, node):
            self.pub = node.create_publisher(Force, "/action", 1)
            node.create_subscription(State, "/obs", lambda msg: None, 1)
            node.create_timer(node.get_period(), lambda: self.pub.publish(Force(newtons=0.0)))
            node.get_logger().info("holding")

    run = ratelab.run(graph="graphs/cartpole-python.toml", nodes={"policy": Hold}, duration_s=3,
                      **VIRTUAL)
    assert not run.metrics["balanced"]  # no force: the pole falls
    assert any("holding" in line and "policy" in line for line in run.log), run.log


def test_a_node_class_s_misuse_typed_at_a_prompt_points_at_its_own_line():
    # Code given to `python -c` (or typed at a prompt) is no file beside the graph: its
    # failures pointed into ratelab's own module (`<ratelab>:NNN`). A text where a number
    # goes is a TypeError naming the field (float("x") failed inside ratelab; "1.5" passed).
    said = in_a_fresh_interpreter("\n".join([
        "import ratelab",
        "from ratelab import Force, State",
        "class Bad:",
        "    def __init__(self, node):",
        "        self.pub = node.create_publisher(Force, '/action', 1)",
        "        node.create_subscription(State, '/obs', lambda m: None, 1)",
        "        node.create_timer(node.get_period(), self.tick)",
        "    def tick(self):",
        "        self.pub.publish(Force(newtons='1.5'))",
        "try:",
        "    ratelab.run(graph='graphs/cartpole-python.toml', nodes={'policy': Bad},",
        "                clock='virtual', duration_s=0.5)",
        "except ratelab.NodeFailed as e:",
        "    print(e)",
        "class Timer:",
        "    def __init__(self, node):",
        "        node.create_timer('x', lambda: None)",
        "try:",
        "    ratelab.run(graph='graphs/cartpole-python.toml', nodes={'policy': Timer},",
        "                clock='virtual', duration_s=0.5)",
        "except ratelab.Error as e:",
        "    print(e)",
        "class NaN:",
        "    def __init__(self, node):",
        "        node.create_timer(float('nan'), print)",
        "try:",
        "    ratelab.run(graph='graphs/cartpole-python.toml', nodes={'policy': NaN},",
        "                clock='virtual', duration_s=0.5)",
        "except ratelab.Error as e:",
        "    print(e)",
    ]))
    field, timer, nan = said.strip().splitlines()
    assert "<string>:25: create_timer's period must be a number of seconds, got float nan" \
        in nan, said
    assert "<string>:9: TypeError: field 'newtons' takes a number, got str '1.5'" in field, said
    assert "<ratelab>" not in said, said
    assert "<string>:17: create_timer's period must be a number of seconds, got str 'x'" \
        in timer, said


# ---- #71: the package in Python's terms ------------------------------------------------------


def test_an_unknown_keyword_names_the_nearest_one():
    with pytest.raises(TypeError) as e:
        ratelab.run(contol_hz=5)
    assert str(e.value) == ("run() got an unexpected keyword argument 'contol_hz'; "
                            "did you mean 'control_hz'?")
    assert isinstance(e.value, ratelab.Error)
    with pytest.raises(TypeError, match="did you mean 'seeds'"):
        ratelab.sweep(seed=[0, 1])
    with pytest.raises(TypeError, match="did you mean 'min_hz'"):
        ratelab.cliff(minhz=4)
    with pytest.raises(TypeError, match="did you mean 'control_hz'"):
        ratelab.sweep(control=[5, 10])
    # Nor do sweep() and cliff(): their settings are keywords of their own.
    for function in (ratelab.sweep, ratelab.cliff):
        with pytest.raises(TypeError, match="'flags'"):
            function(flags=["--seeds", "0"])
    with pytest.raises(TypeError, match="did you mean 'dir'"):
        ratelab.exercise("ex1", dri="exercises")
    # exercise() takes the graph's settings as keywords, not flags; no faults (an exercise
    # injects its own); its refusals name the keyword, never a flag.
    with pytest.raises(TypeError, match="'flags'"):
        ratelab.exercise("ex1", flags=["--rate", "policy=10"])
    with pytest.raises(TypeError, match="'stall': an exercise injects its own faults"):
        ratelab.exercise("ex1", stall={"policy": (1.0, 0.5)})
    with pytest.raises(TypeError, match="'flags': each of `ratelab exercise`'s graph settings"):
        ratelab.exercise("ex1", flags=["--graph", "graphs/estimator.toml"])
    with pytest.raises(ValueError, match="nobody") as e:
        ratelab.exercise("ex1", {"fails_at_hz": 5, "why": "?"}, rate={"nobody": np.float64(10)})
    assert "rate" in str(e.value) and "--" not in str(e.value), str(e.value)
    # No front end parses another's arguments: run() takes no flags.
    with pytest.raises(TypeError, match="'flags'"):
        ratelab.run(flags=["--executor", "single_threaded"])
    # The signature is still the function's own, for help() and an editor.
    import inspect
    params = inspect.signature(ratelab.run).parameters
    assert "control_hz" in params and "stall" in params and "flags" not in params


def test_a_node_name_the_graph_does_not_have_is_refused():
    from ratelab import Force, State

    class Hold:
        def __init__(self, node):
            self.pub = node.create_publisher(Force, "/action", 1)
            node.create_subscription(State, "/obs", lambda msg: None, 1)

    with pytest.raises(ValueError) as e:
        ratelab.run(graph="graphs/cartpole-python.toml", nodes={"polcy": Hold}, duration_s=1,
                    **VIRTUAL)
    # The bad name, and the graph's Python nodes to choose from.
    assert "polcy" in str(e.value) and "policy" in str(e.value), str(e.value)
    # On the chapter's graph (no Python node at all) it is refused too, not ignored.
    with pytest.raises(ValueError) as e:
        ratelab.run(nodes={"policy": Hold}, duration_s=1, **VIRTUAL)
    assert "policy" in str(e.value)


def test_numpy_scalars_and_arrays_are_numbers_and_lists():
    plain = ratelab.run(control_hz=10, queue_depth=100, seed=2, duration_s=10, **VIRTUAL)
    numpy = ratelab.run(control_hz=np.float64(10), queue_depth=np.int64(100), seed=np.int64(2),
                        duration_s=np.float32(10), **VIRTUAL)
    assert numpy.metrics_json == plain.metrics_json
    assert ratelab.run(control_hz=np.int32(5), duration_s=1, **VIRTUAL).metrics["control_hz"] == 5
    # Per-node and per-topic values, and a list as an array.
    by_node = ratelab.run(rate={"policy": np.float64(10)}, depth={"/obs": np.int64(100)},
                          seed=2, **VIRTUAL)
    assert by_node.metrics["control_hz"] == 10 and by_node.metrics["queue_depth"] == 100
    offsets = ratelab.run(phase_offset_ms=np.array([0.0, 5.0, 10.0]), duration_s=2, **VIRTUAL)
    assert offsets.metrics_json == ratelab.run(phase_offset_ms=[0, 5, 10], duration_s=2,
                                               **VIRTUAL).metrics_json
    # A bool is not a number; a float is not a count.
    with pytest.raises(TypeError, match="control_hz.*Hz"):
        ratelab.run(control_hz=True)
    with pytest.raises(TypeError, match="queue_depth.*messages"):
        ratelab.run(queue_depth=2.5)
    # sweep and cliff: arrays, NumPy scalars.
    table = ratelab.sweep(control_hz=np.array([50.0, 5.0]), seeds=np.arange(2),
                          sensor_hz=np.float64(50), queue_depth=np.int64(1),
                          duration_s=np.float64(2))
    assert table.csv == ratelab.sweep(control_hz=[50, 5], seeds=[0, 1], duration_s=2).csv
    assert ratelab.sweep(control_hz=np.float64(50), seeds=np.int64(0), duration_s=1).rows[0][
        "balanced"] is True
    cliff = ratelab.cliff(seeds=np.array([0]), min_hz=np.float64(4), max_hz=np.int64(12),
                          step_hz=np.float32(0.5))
    assert cliff.csv == ratelab.cliff(seeds=[0], min_hz=4, max_hz=12, step_hz=0.5).csv


def test_a_run_says_whether_it_balanced_or_fell():
    up = ratelab.run(duration_s=1, **VIRTUAL)
    assert repr(up) == "<ratelab.Run balanced 1.0 s, control 50 Hz, seed 0, virtual clock>"
    down = ratelab.run(control_hz=5, **VIRTUAL)
    fell = down.metrics["fell_at_s"]
    assert repr(down) == f"<ratelab.Run fell at {fell:.2f} s, control 5 Hz, seed 0, virtual clock>"
    html = down._repr_html_()
    assert html.startswith("<table") and "fell at" in html and "control_hz" in html
    # Jupyter's tables of a sweep and a cliff, and what they print.
    table = ratelab.sweep(control_hz=[50, 5], seeds=[0], duration_s=2)
    assert isinstance(table, ratelab.Table) and isinstance(table, ratelab.Sweep)
    assert repr(table).startswith("<ratelab.Sweep 2 runs: 1 balanced, 1 fell")
    assert "<th>control_hz</th>" in table._repr_html_()
    cliff = ratelab.cliff(seeds=[0], min_hz=4, max_hz=12, step_hz=0.5)
    assert repr(cliff).startswith("<ratelab.Cliff seed 0: falls at ")
    # Text is escaped.
    odd = ratelab.Table("name,value\n<b>,a&b\n")
    assert "&lt;b&gt;" in odd._repr_html_() and "a&amp;b" in odd._repr_html_()


def test_a_node_declares_and_reads_parameters_as_rclpy_s(tmp_path):
    from ratelab import Force, State

    # The chapter's Python graph with a parameter the graph file gives (an override).
    text = (ROOT / "graphs/cartpole-python.toml").read_text()
    script = ROOT / "graphs/nodes/scripted_balancer.py"
    text = text.replace('script = "nodes/scripted_balancer.py"', f'script = "{script}"')
    text = text.replace('class = "ScriptedBalancer"',
                        'class = "ScriptedBalancer"\nparams = { gain = 3.0 }')
    assert "params = { gain = 3.0 }" in text
    graph = tmp_path / "tuned.toml"
    graph.write_text(text)
    said = []

    class Tuned:
        def __init__(self, node):
            gain = node.declare_parameter("gain", 10.0)  # the graph file's 3.0 wins
            hold = node.declare_parameter("hold_n", 0.5)  # not in the file: the default
            said.append((gain.name, gain.value, hold.value, node.get_parameter("hold_n").value,
                         node.get_parameter("gain").value, node.has_parameter("gain"),
                         node.has_parameter("nope")))
            try:
                node.declare_parameter("gain", 1.0)
            except Exception as e:  # noqa: BLE001 (rclpy's exception, by its name)
                said.append(type(e).__name__)
            try:
                node.get_parameter("nope")
            except Exception as e:  # noqa: BLE001
                said.append(type(e).__name__)
            self.pub = node.create_publisher(Force, "/action", 1)
            node.create_subscription(State, "/obs", lambda msg: None, 1)
            node.create_timer(node.get_period(), lambda: self.pub.publish(Force(newtons=0.0)))

    ratelab.run(graph=graph, nodes={"policy": Tuned}, duration_s=1, **VIRTUAL)
    assert said == [("gain", 3.0, 0.5, 0.5, 3.0, True, False),
                    "ParameterAlreadyDeclaredException", "ParameterNotDeclaredException"]


def test_the_defaults_are_ratelab_run_s(tmp_path):
    # One default clock for every front end: the real one, as `ratelab run`'s.
    out = tmp_path / "out"
    subprocess.run([str(COMMAND), "run", "--duration", "1", "--out", str(out)],
                   capture_output=True, timeout=120)
    command = json.loads((out / "metrics.json").read_text())
    run = ratelab.run(duration_s=1)
    assert run.metrics["clock"] == command["clock"] == "real"
    same = ["clock", "seed", "duration_s", "control_hz", "sensor_hz", "queue_depth", "policy",
            "graph"]
    assert {k: run.metrics[k] for k in same} == {k: command[k] for k in same}
    assert set(run.metrics) == set(command)
    assert "real clock" in repr(run)


FLAG = re.compile(r"--[a-z]")


@pytest.mark.parametrize("settings, name", [
    ({"control_hz": 0}, "control_hz"),
    ({"sensor_hz": 0}, "sensor_hz"),
    ({"queue_depth": 0}, "queue_depth"),
    ({"queue_depth": 2**20 + 1}, "queue_depth"),
    ({"queue_depth": 2**70}, "queue_depth"),
    ({"trace_every": 2**64}, "trace_every"),
    ({"control_hz": 10**400}, "control_hz"),
    ({"depth": {"/obs": 2**64}}, "depth"),
    ({"duration_s": 0}, "duration_s"),
    ({"trace_every": 0}, "trace_every"),
    ({"seed": -1}, "seed"),
    ({"clock": "sundial"}, "clock"),
    ({"rate": {"policy": 0}}, "rate"),
    ({"executor": "bogus"}, "executor"),
    ({"phase_offset_ms": [0, 5]}, "phase_offset_ms"),
])
def test_errors_name_python_parameters_never_flags(settings, name):
    with pytest.raises(ValueError) as e:
        ratelab.run(**{"duration_s": 1, **VIRTUAL, **settings})
    line = str(e.value)
    assert name in line and not FLAG.search(line), line
    assert isinstance(e.value, ratelab.Error)
    # A number too large is out of range, said as such (not "at least 1", not "got list").
    value = next(iter(settings.values()))
    huge = lambda v: isinstance(v, int) and v > 2**40  # noqa: E731
    if huge(value) or isinstance(value, dict) and any(huge(v) for v in value.values()):
        assert "at least 1" not in line and "got list" not in line, line
        assert "range" in line or "in 1..=" in line or "too large" in line, line


def test_dir_lists_the_public_api_not_the_imports():
    """`dir(ratelab)` (tab completion) offers the API and the message classes, not the
    modules and typing names the package imports (a learner's trial saw `csv`, `Any`)."""
    names = dir(ratelab)
    for public in ratelab.__all__ + ["State", "Force", "__version__"]:
        assert public in names, public
        assert hasattr(ratelab, public), public
    for private in ["csv", "json", "os", "functools", "Any", "Callable", "dataclass"]:
        assert private not in names, private
