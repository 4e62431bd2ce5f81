"""The Python package, installed from its wheel into a fresh virtual environment
(scripts/test-python.sh): `ratelab.run` against the command line and the reference runs,
a callable brain against the same brain from a file, errors as exceptions, Ctrl-C, and the
installed `ratelab` command."""

import _thread
import importlib.util
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
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
# interpreter).
CASES = {
    "default": {},
    "control5": {"control_hz": 5},
    "control10-depth100-seed2": {"seed": 2, "control_hz": 10, "queue_depth": 100},
    "python": {"graph": "graphs/cartpole-python.toml"},
}


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
    run = ratelab.run(graph=graph, duration_s=5)
    assert run.estimator == json.loads((out / "estimator.json").read_text())
    assert run.estimator["topic"] == "/state" and run.estimator["estimator"] == "estimator"
    # Every step but the first (the first estimate is out 1 ms after t = 0).
    assert run.estimator["samples"] == run.metrics["steps"] - 1
    # The low-pass at 20 Hz lags the angular velocity by about 1/(2π·20) s = 8 ms.
    assert 4 <= run.estimator["pole_angvel_lag_ms"] <= 12
    assert any(line.startswith("estimate on /state vs the plant") for line in run.summary)
    assert ratelab.run(duration_s=1).estimator is None


def test_the_rate_cliff_is_the_chapter_s():
    assert ratelab.run().metrics["balanced"]
    fell = ratelab.run(control_hz=5)
    assert not fell.metrics["balanced"]
    assert 0 < fell.metrics["fell_at_s"] < 2.0
    deep = ratelab.run(control_hz=10, queue_depth=100, seed=2)
    assert deep.metrics["queue_depth"] == 100


def load_brain():
    spec = importlib.util.spec_from_file_location("scripted_brain", ROOT / "graphs/brains/scripted.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.act


def test_a_callable_brain_equals_the_same_brain_from_a_file():
    from_file = ratelab.run(policy="graphs/brains/scripted.py", control_hz=10)
    from_here = ratelab.run(policy=load_brain(), control_hz=10)
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

    run = ratelab.run(policy=act, duration_s=1.0)
    assert calls and calls[0] == (5,)
    assert any("first observation float32" in line for line in run.log), run.log
    # Nothing was written over the caller's own output, which is its own again.
    print("after")
    assert "after" in capsys.readouterr().out


def test_bad_input_is_an_exception_with_the_one_line():
    with pytest.raises(ValueError) as e:
        ratelab.run(control_hz=-1)
    assert "\n" not in str(e.value) and "control-hz" in str(e.value)
    with pytest.raises(ValueError):
        ratelab.run(clock="sundial")
    with pytest.raises(ValueError):
        ratelab.run(duration_s="ten")
    with pytest.raises(FileNotFoundError) as e:
        ratelab.run(graph="graphs/no-such-graph.toml")
    assert "no-such-graph.toml" in str(e.value)
    with pytest.raises(FileNotFoundError):
        ratelab.run(policy="no-such-checkpoint.pt")


def test_a_trace_too_large_to_hold_is_refused_before_the_run():
    # Ten years of run time: its trace would be 15.8 G steps; run, it would never end.
    started = time.monotonic()
    with pytest.raises(ratelab.TraceTooLarge) as e:
        ratelab.run(duration_s=315360000.0)
    assert time.monotonic() - started < 10.0
    assert isinstance(e.value, MemoryError) and isinstance(e.value, ratelab.Error)
    line = str(e.value)
    assert "\n" not in line and "MAX_HELD_TRACE_VALUES" in line, line
    assert "trace_every=2820" in line, line
    # Thinned as asked: steps 1, 11, ..., 101; the metrics count every step.
    run = ratelab.run(duration_s=2.0, trace_every=10)
    assert [int(s) for s in run.trace["step"]] == list(range(1, 102, 10))
    assert run.metrics["steps"] == 101


def test_an_output_is_not_replaced_without_force(tmp_path):
    ratelab.run(duration_s=0.5, out=tmp_path)
    with pytest.raises(FileExistsError) as e:
        ratelab.run(duration_s=0.5, out=tmp_path)
    assert "--force" in str(e.value)
    ratelab.run(duration_s=0.5, out=tmp_path, force=True)


def test_a_brain_that_raises_fails_its_node_and_keeps_the_figures():
    ticks = []

    def act(obs):
        ticks.append(obs)
        if len(ticks) == 10:
            raise RuntimeError("too far right")
        return 0.5

    with pytest.raises(ratelab.NodeFailed) as e:
        ratelab.run(policy=act)
    assert "too far right" in str(e.value) and "policy" in str(e.value)
    assert e.value.run.metrics["balanced"] is False
    assert e.value.run.metrics["steps"] > 0


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
    assert ratelab.run(duration_s=0.5).metrics["steps"] == 26  # t = 0, 20, …, 500 ms


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
    drawn = ratelab.run(graph="graphs/cartpole-camera.toml", duration_s=3)
    run = ratelab.run(graph="graphs/cartpole-camera-mujoco.toml", duration_s=3)
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
    assert not ratelab.run(control_hz=falls).metrics["balanced"]
    assert ratelab.run(control_hz=balances).metrics["balanced"]
    with pytest.raises(ValueError) as e:
        ratelab.cliff(min_hz=20, max_hz=10)
    assert "--min-hz" in str(e.value)


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
    with pytest.raises(ValueError):
        ratelab.exercise("ex99", {"why": "?"}, dir=folder)


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
    from_file = ratelab.run(graph="graphs/cartpole-python.toml")
    given = ratelab.run(graph="graphs/cartpole-python.toml",
                        nodes={"policy": module.ScriptedBalancer})
    assert given.trace_csv == from_file.trace_csv
    assert given.metrics_json == from_file.metrics_json
    # `import ratelab` is still the package after Python nodes ran (their message classes
    # joined it).
    assert sys.modules["ratelab"] is ratelab and ratelab.Force(newtons=1.0).newtons == 1.0
    with pytest.raises(ValueError):
        ratelab.run(graph="graphs/cartpole-python.toml", nodes={"policy": "ScriptedBalancer"})


def test_a_node_class_defined_in_a_cell_runs_here():
    from ratelab import Force, State

    class Hold:
        def __init__(self, node):
            self.pub = node.create_publisher(Force, "/action", 1)
            node.create_subscription(State, "/obs", lambda msg: None, 1)
            node.create_timer(node.get_period(), lambda: self.pub.publish(Force(newtons=0.0)))
            node.get_logger().info("holding")

    run = ratelab.run(graph="graphs/cartpole-python.toml", nodes={"policy": Hold}, duration_s=3)
    assert not run.metrics["balanced"]  # no force: the pole falls
    assert any("holding" in line and "policy" in line for line in run.log), run.log
