"""ratelab in Python: the lab's runs in your notebook, script or pytest.

    import ratelab
    run = ratelab.run(control_hz=5)          # the chapter's graph, virtual clock, seed 0
    run.metrics["balanced"], run.metrics["fell_at_s"]
    run.trace["pole_angle_rad"]              # NumPy arrays, one value per actuator step

A run is `ratelab run --out DIR` made in this process by the same code: `run.metrics` holds
`metrics.json`'s keys, `run.trace` `trace.csv`'s columns, `run.log` `log.txt`'s lines (what
each means: docs/metrics.md). A brain (`policy=`) may be a function defined here, in a
notebook cell: it runs in this interpreter and, under the virtual clock, gives exactly the
run the same function gives from a file. The `ratelab` command this package installs is
the whole command line (`ratelab lab`, `ratelab launch`, …).

Errors are exceptions carrying ratelab's one line: `ValueError` for a bad setting,
`FileNotFoundError` for a missing file, `FileExistsError` for an output that exists (pass
`force=True`), `NodeFailed` when a node of the run failed (its `.run` holds the figures up
to then), `TraceTooLarge` (a `ratelab.Error` and a `MemoryError`) before a run whose trace
would not fit in memory (keep one step in N with `trace_every=N`, or write the trace to a
file as the run goes with the command `ratelab run --out DIR`). Ctrl-C (KeyboardInterrupt)
stops a run.
"""

from __future__ import annotations

import csv
import io
import json
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

from . import _native

if TYPE_CHECKING:
    from ._messages import Force, Position, State, Time  # noqa: F401


def __getattr__(name: str) -> Any:
    # The message classes Python nodes use (`from ratelab import State, Force`), made by
    # ratelab's message registry when first asked for.
    if name in ("State", "Position", "Force", "Time") or name[:1].isupper():
        _native.install_messages()
        if name in globals():
            return globals()[name]
    raise AttributeError(f"module 'ratelab' has no attribute {name!r}")

__version__: str = _native.__version__

__all__ = [
    "Run",
    "Table",
    "Check",
    "Prediction",
    "Exercise",
    "NodeFailed",
    "NoPrediction",
    "Error",
    "TraceTooLarge",
    "run",
    "sweep",
    "cliff",
    "exercise",
    "exercises",
    "TRACE_COLUMNS",
]

#: An exercise asked for before its prediction was written (a ValueError).
NoPrediction = _native.NoPrediction


class Error(Exception):
    """An error of ratelab's own kind (bad input is a `ValueError`, a missing file a
    `FileNotFoundError`, as Python's own)."""


class TraceTooLarge(Error, MemoryError):
    """A run refused before it started: the trace `run` returns (its text and its NumPy
    arrays) would hold more values, rows x columns, than ratelab's bound
    (`ratelab::limits::MAX_HELD_TRACE_VALUES`, 64 Mi: a day of the chapter's graph fits).
    The message names the `trace_every=N` that fits; `ratelab run --out DIR` writes the
    whole trace to `trace.csv` as the run goes instead, holding none of it."""


#: `trace.csv`'s columns as `Run.trace` names them: units in the names where one applies.
#: The per-topic counters (`obs_published`, `cmd_lost`, …) keep their names (messages).
TRACE_COLUMNS: Dict[str, str] = {
    "step": "step",
    "t_ns": "t_ns",
    "pole_angle": "pole_angle_rad",
    "cart_pos": "cart_pos_m",
    "action": "action_motor",  # motor command in [-1, 1], x 10 N
    "latency_ns": "latency_ns",  # NaN before the first sensed force
    "nonfinite": "nonfinite",
    "fell": "fell",
}

PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True)
class Run:
    """One run's results, as `ratelab run --out` writes them."""

    #: `metrics.json` as a dict (docs/metrics.md).
    metrics: Dict[str, Any]
    #: `trace.csv`'s columns as NumPy arrays, one value per actuator step (with
    #: `trace_every=N`, per N-th step and the last), named as `TRACE_COLUMNS` says (units in
    #: the names).
    trace: Dict[str, Any]
    #: `log.txt`'s lines: what the nodes wrote, stamped `[t=1.234 s node]`.
    log: List[str]
    #: The summary `ratelab run` prints (without the wall time).
    summary: List[str]
    #: The recording written (`record=`), or None.
    recording: Optional[str]
    #: `metrics.json`'s exact text.
    metrics_json: str
    #: `trace.csv`'s exact text.
    trace_csv: str
    #: The wall time the run itself took, s (`ratelab run`'s summary's `wall`).
    wall_s: float
    #: With an estimator in the graph, `estimator.json` as a dict: its RMS error per state
    #: component (m, m/s, rad, rad/s) and its lag, ms, against the plant's true state
    #: (docs/metrics.md); None without one.
    estimator: Optional[Dict[str, Any]] = None

    def __repr__(self) -> str:
        head = self.summary[0] if self.summary else "run"
        return f"<ratelab.Run {head}>"


class Table:
    """A table of results (`sweep`, `cliff`): `rows` (one dict per row), `columns` (one list
    per column), `csv` (the text `ratelab sweep --csv` writes), `to_pandas()`."""

    def __init__(self, csv_text: str):
        self.csv: str = csv_text
        reader = csv.DictReader(io.StringIO(csv_text))
        self.rows: List[Dict[str, Any]] = [
            {k: _cell(v) for k, v in row.items()} for row in reader
        ]
        names = reader.fieldnames or []
        self.columns: Dict[str, List[Any]] = {n: [r[n] for r in self.rows] for n in names}

    def __len__(self) -> int:
        return len(self.rows)

    def __iter__(self):
        return iter(self.rows)

    def __getitem__(self, column: str) -> List[Any]:
        return self.columns[column]

    def to_pandas(self):
        """The table as a pandas DataFrame (pandas must be installed)."""
        import pandas as pd

        return pd.DataFrame(self.columns)

    def __repr__(self) -> str:
        return f"<ratelab.Table {len(self.rows)} rows: {', '.join(self.columns)}>"


def _cell(text: str) -> Any:
    """A CSV cell as the value it writes: a bool, an int, a float, None (empty) or text."""
    if text == "":
        return None
    if text in ("true", "false"):
        return text == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _list(name: str, values: Union[float, Sequence[float]]) -> str:
    if isinstance(values, (int, float)) and not isinstance(values, bool):
        values = [values]
    values = list(values)
    if not values:
        raise ValueError(
            f"{name}: an empty list runs nothing (every check over it would pass without a run); give at least one value"
        )
    return ",".join(_number(name, v) for v in values)


class NodeFailed(RuntimeError):
    """A node of the run failed (a brain or node raised): the message is ratelab's line,
    `.run` the run's figures up to the failure (None for a sweep's)."""

    def __init__(self, message: str, run: Optional[Run]):
        super().__init__(message)
        self.run = run


def _trace_arrays(columns: Sequence[Any]) -> Dict[str, Any]:
    """`(name, dtype, bytes)` per column (made from trace.csv's text) as NumPy arrays."""
    import numpy as np

    return {TRACE_COLUMNS.get(n, n): np.frombuffer(b, dtype=k) for n, k, b in columns}


def _flag_pairs(flag: str, value: Union[None, Mapping[str, Any], Sequence[str]]) -> List[str]:
    """`{"policy": 10}` as `--rate policy=10`; a list of `"policy=10"` strings as given."""
    if value is None:
        return []
    items = value.items() if isinstance(value, Mapping) else None
    out: List[str] = []
    if items is not None:
        for k, v in items:
            out += [flag, f"{k}={v}"]
    else:
        if isinstance(value, str):
            value = [value]
        for v in value:
            out += [flag, str(v)]
    return out


def _number(name: str, value: Any) -> str:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    return repr(value) if isinstance(value, float) else str(value)


def run(
    graph: Optional[PathLike] = None,
    *,
    clock: str = "virtual",
    seed: int = 0,
    duration_s: float = 10.0,
    control_hz: Optional[float] = None,
    sensor_hz: Optional[float] = None,
    queue_depth: Optional[int] = None,
    rate: Optional[Mapping[str, float]] = None,
    depth: Optional[Mapping[str, int]] = None,
    qos: Union[None, str, Sequence[str]] = None,
    link: Union[None, str, Sequence[str]] = None,
    policy: Union[None, str, PathLike, Callable[[Any], Any]] = None,
    record: Optional[PathLike] = None,
    out: Optional[PathLike] = None,
    force: bool = False,
    nodes: Optional[Mapping[str, type]] = None,
    trace_every: int = 1,
    flags: Sequence[str] = (),
) -> Run:
    """Run a graph, as `ratelab run` does, and return its figures.

    graph: a graph file (default the chapter's: sensor -> /obs -> policy -> /action ->
        actuator). clock: "virtual" (deterministic: same settings, same bytes) or "real".
    seed: the reset seed. duration_s: run time in seconds.
    control_hz, sensor_hz (Hz), queue_depth (messages): the chapter's three knobs.
    rate: per-node rates in Hz ({"policy": 10}); depth: per-topic history depths
        ({"/obs": 100}); qos, link: `--qos` and `--link` values ("/obs:history=keep_all").
    policy: the brain: "scripted" (default), a checkpoint path, "FILE.py[:FUNCTION]", or a
        callable `f(obs) -> action` (obs a NumPy float32[5]; action a float in [-1, 1]).
    record: write a rerun recording to this path. out: also write metrics.json, trace.csv
        and log.txt to this folder (force: replace existing files).
    nodes: classes for the graph's Python nodes, by node name ({"policy": MyNode}): each
        is made from the class given (defined here, in a notebook cell) instead of its
        graph file's script, and driven exactly as one from a file.
    trace_every: keep one actuator step in this many in `Run.trace` (steps 1, 1 + N, ... and
        the last; `--trace-every`): a long run's trace in proportion to what you ask. The
        metrics count every step.
    flags: any other `ratelab run` flags, as strings (["--executor", "single"]).

    Raises ValueError, FileNotFoundError, FileExistsError, NodeFailed, KeyboardInterrupt,
    and TraceTooLarge (a MemoryError) before a run whose trace would not fit in memory.
    """
    args: List[str] = ["--clock", str(clock), "--seed", str(int(seed))]
    args += ["--duration", _number("duration_s", duration_s)]
    if graph is not None:
        args += ["--graph", os.fspath(graph)]
    if control_hz is not None:
        args += ["--control-hz", _number("control_hz", control_hz)]
    if sensor_hz is not None:
        args += ["--sensor-hz", _number("sensor_hz", sensor_hz)]
    if queue_depth is not None:
        args += ["--queue-depth", _number("queue_depth", queue_depth)]
    args += _flag_pairs("--rate", rate)
    args += _flag_pairs("--depth", depth)
    args += _flag_pairs("--qos", qos)
    args += _flag_pairs("--link", link)
    brain = None
    if callable(policy):
        brain = policy
    elif policy is not None:
        args += ["--policy", os.fspath(policy)]
    if record is not None:
        args += ["--record", os.fspath(record)]
    if out is not None:
        args += ["--out", os.fspath(out)]
    if force:
        args.append("--force")
    if trace_every != 1:
        args += ["--trace-every", _number("trace_every", trace_every)]
    args += [str(f) for f in flags]
    classes = list((nodes or {}).items())
    for node, cls in classes:
        if not isinstance(cls, type):
            raise ValueError(f"nodes[{node!r}] must be a class, got {type(cls).__name__}")
    try:
        files = _native.run(args, brain, classes)
    except _native.TraceTooLarge as e:
        raise TraceTooLarge(str(e)) from None
    result = Run(
        metrics=json.loads(files["metrics_json"]),
        trace=_trace_arrays(files["trace_columns"]),
        log=files["log"].splitlines(),
        summary=list(files["summary"]),
        recording=files["recording"],
        metrics_json=files["metrics_json"],
        trace_csv=files["trace_csv"],
        wall_s=files["wall_s"],
        estimator=None
        if files["estimator_json"] is None
        else json.loads(files["estimator_json"]),
    )
    if files["failed"] is not None:
        raise NodeFailed(files["failed"], result)
    return result


def sweep(
    graph: Optional[PathLike] = None,
    *,
    control_hz: Union[float, Sequence[float]] = (50, 25, 20, 15, 10, 5),
    sensor_hz: Union[float, Sequence[float]] = 50,
    queue_depth: Union[int, Sequence[int]] = 1,
    seeds: Union[int, Sequence[int]] = (0, 1, 2),
    clock: Union[str, Sequence[str]] = "virtual",
    policy: Union[str, PathLike] = "scripted",
    duration_s: float = 10.0,
    flags: Sequence[str] = (),
) -> Table:
    """Every combination of the given rates, depths, seeds and clocks, one run each, on every
    core (as `ratelab sweep`): a `Table` with a row per run (its point and figures: the
    columns `ratelab sweep --csv` writes). A run that failed a node raises NodeFailed once
    all have run (its `.run` is None)."""
    args: List[str] = ["--control-hz", _list("control_hz", control_hz)]
    args += ["--sensor-hz", _list("sensor_hz", sensor_hz)]
    args += ["--queue-depth", _list("queue_depth", queue_depth)]
    args += ["--seeds", _list("seeds", seeds)]
    args += ["--clock", clock if isinstance(clock, str) else ",".join(clock)]
    args += ["--policy", os.fspath(policy), "--duration", _number("duration_s", duration_s)]
    if graph is not None:
        args += ["--graph", os.fspath(graph)]
    args += [str(f) for f in flags]
    text, failed = _native.sweep(args)
    table = Table(text)
    if failed is not None:
        raise NodeFailed(failed, None)
    return table


def cliff(
    graph: Optional[PathLike] = None,
    *,
    seeds: Union[int, Sequence[int]] = (0, 1, 2),
    sensor_hz: float = 50,
    queue_depth: int = 1,
    min_hz: float = 1,
    max_hz: float = 50,
    step_hz: float = 0.1,
    policy: Union[str, PathLike] = "scripted",
    duration_s: float = 10.0,
    flags: Sequence[str] = (),
) -> Table:
    """Per seed, the highest control rate at which the pole falls within `duration_s`, to
    `step_hz` (as `ratelab cliff`; virtual clock): a `Table` with the columns seed,
    falls_at_hz, balances_at_hz (None when there is none) and runs."""
    args: List[str] = ["--seeds", _list("seeds", seeds)]
    args += ["--sensor-hz", _number("sensor_hz", sensor_hz)]
    args += ["--queue-depth", _number("queue_depth", queue_depth)]
    args += ["--min-hz", _number("min_hz", min_hz), "--max-hz", _number("max_hz", max_hz)]
    args += ["--step", _number("step_hz", step_hz)]
    args += ["--policy", os.fspath(policy), "--duration", _number("duration_s", duration_s)]
    if graph is not None:
        args += ["--graph", os.fspath(graph)]
    args += [str(f) for f in flags]
    return Table(_native.cliff(args))


@dataclass(frozen=True)
class Check:
    """One of an exercise's checks: what was checked, and whether it held."""

    name: str
    passed: bool


@dataclass(frozen=True)
class Prediction:
    """One key of the learner's prediction beside the outcome: the key, the sentence saying
    both ("You predicted the pole first fails at 10 Hz; it first fell at 5 Hz."), and the
    verdict: "right", "missed", "unreadable" (missing, or not of its type) or "open" (not
    graded: the outcome left the key moot)."""

    key: str
    said: str
    verdict: str

    @property
    def right(self) -> bool:
        """It held (or was not graded): it does not keep the exercise from passing."""
        return self.verdict in ("right", "open")


@dataclass(frozen=True)
class Exercise:
    """What an exercise found (`ratelab exercise`)."""

    #: Its checks, in the order it prints them.
    checks: List[Check]
    #: The prediction beside the outcome, one sentence per predicted key.
    reconcile: List[str]
    #: Checks that failed plus predictions that missed or could not be read.
    not_passed: int
    #: The report `ratelab exercise` prints, a line each.
    report: List[str]
    #: The prediction beside the outcome, a key each, with its verdict.
    predictions: List[Prediction]

    @property
    def passed(self) -> bool:
        """Every check held and every prediction was right (exit 0 of the command)."""
        return self.not_passed == 0

    @property
    def failed_checks(self) -> List[Check]:
        """The checks that did not hold."""
        return [c for c in self.checks if not c.passed]

    @property
    def missed(self) -> List[Prediction]:
        """The predictions that missed or could not be read."""
        return [p for p in self.predictions if not p.right]


def exercise(
    which: str,
    prediction: Optional[Mapping[str, Any]] = None,
    *,
    dir: PathLike = "exercises",
    graph: Optional[PathLike] = None,
    flags: Sequence[str] = (),
) -> Exercise:
    """Run exercise `which` ("ex1", …) as `ratelab exercise` does, with `prediction` (the keys
    its file's [prediction] asks for, and "why") in place of the learner's file's when given.

    Raises NoPrediction (a ValueError) when there is no prediction yet, ValueError for an
    unknown exercise or bad input, FileNotFoundError for a missing folder or file.
    """
    args: List[str] = ["--dir", os.fspath(dir)]
    if graph is not None:
        args += ["--graph", os.fspath(graph)]
    args += [str(f) for f in flags]
    given = None if prediction is None else json.dumps(dict(prediction))
    found = _native.exercise(str(which), args, given)
    return Exercise(
        checks=[Check(name, passed) for name, passed in found["checks"]],
        reconcile=list(found["reconcile"]),
        not_passed=int(found["not_passed"]),
        report=list(found["lines"]),
        predictions=[Prediction(k, said, v) for k, said, v in found["predictions"]],
    )


def exercises() -> List[Dict[str, str]]:
    """The exercises, in order: their `id` ("ex1"), `file` in the exercises folder
    ("ex1_rate_cliff.toml") and `title`."""
    return [{"id": i, "file": f, "title": t} for i, f, t in _native.exercises()]
