"""ratelab in Python: the lab's runs in your notebook, script or pytest.

>>> import ratelab
>>> run = ratelab.run(control_hz=5, clock="virtual")  # the chapter's graph, seed 0, 10 s
>>> run
<ratelab.Run fell at ... s, control 5 Hz, seed 0, virtual clock>
>>> run.metrics["balanced"], run.metrics["fell_at_s"]
(False, ...)
>>> len(run.trace["pole_angle_rad"]) == run.metrics["steps"]  # NumPy arrays, one value a step
True

A run is `ratelab run --out DIR` made in this process by the same code, with the same
defaults (the real clock among them: `clock="virtual"` is the deterministic one, the same
settings giving the same bytes): `run.metrics` holds `metrics.json`'s keys, `run.trace`
`trace.csv`'s columns, `run.log` `log.txt`'s lines (what each means: docs/metrics.md). A
brain (`policy=`, of `run`, `sweep` and `cliff` alike) may be a function defined here, in a
notebook cell: it runs in this interpreter and, under the virtual clock, gives exactly the
run the same function gives from a file. The `ratelab` command this package installs is the whole command line
(`ratelab lab`, `ratelab launch`, …).

Errors are exceptions carrying ratelab's one line, which names the Python parameter: a
`ratelab.Error` each where it is ratelab's own. `SettingError` (a `ValueError`) for a bad
value, `SettingTypeError` (a `TypeError`) for a value of the wrong type or an unknown
keyword, `FileNotFoundError` for a missing file, `FileExistsError` for an output that exists
(pass `force=True`), `IsADirectoryError` for a recording given a folder, `OSError` where the
file system refuses an output, `NodeFailed` (a `RuntimeError`) when a node of the run failed (its
`.run` holds the figures up to then), `TraceTooLarge` (a `MemoryError`) before a run whose
trace would not fit in memory (keep one step in N with `trace_every=N`, or write the trace
to a file as the run goes with the command `ratelab run --out DIR`), `NoPrediction` (a
`ValueError`) for an exercise whose prediction is not written yet. Ctrl-C
(KeyboardInterrupt) stops a run or an exercise.
"""

from __future__ import annotations

import csv
import functools
import inspect
import io
import json
import numbers
import os
import warnings
from dataclasses import dataclass
from typing import (
    TYPE_CHECKING,
    Any,
    Callable,
    Dict,
    Iterable,
    List,
    Mapping,
    Optional,
    Sequence,
    Tuple,
    Union,
)

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


def __dir__() -> List[str]:
    # What `dir(ratelab)` and tab completion offer: the public API and the message classes,
    # not the modules and typing names this file imports.
    return sorted(set(__all__) | {"__version__", "State", "Position", "Force", "Time"})

__all__ = [
    "Run",
    "Table",
    "Sweep",
    "Cliff",
    "Check",
    "Prediction",
    "Exercise",
    "NodeFailed",
    "NoPrediction",
    "Error",
    "SettingError",
    "SettingTypeError",
    "TraceTooLarge",
    "RunInProgress",
    "run",
    "sweep",
    "cliff",
    "exercise",
    "exercises",
    "copy_exercises",
    "TRACE_COLUMNS",
]

class Error(Exception):
    """An error of ratelab's own kind. Each is also the Python exception of its cause: a bad
    setting a `ValueError` (`SettingError`) or a `TypeError` (`SettingTypeError`), a failed
    node a `RuntimeError` (`NodeFailed`), a trace too large a `MemoryError`
    (`TraceTooLarge`), an exercise without a prediction a `ValueError` (`NoPrediction`)."""


class SettingError(Error, ValueError):
    """A setting ratelab refuses (`run(control_hz=0)`): the message names the Python
    parameter and its unit."""


class SettingTypeError(Error, TypeError):
    """A setting of the wrong type (`run(control_hz="fast")`), or a keyword the function
    does not take (`run(contol_hz=5)`: the message names the nearest one it does take)."""


class NoPrediction(Error, ValueError):
    """An exercise asked for before its prediction was written, or with part of it left out
    (`ratelab exercise` refuses it too): the message names the learner's file and what the
    prediction lacks (every key it asks for, when it has none of them)."""


class RunInProgress(Error, RuntimeError):
    """`run`, `sweep`, `cliff` or `exercise` called from inside a run's brain or node (or a
    script's top level, which runs again when ratelab loads it): the run in progress holds
    the process's one run until that callback returns, so the call is refused at once
    rather than left to wait for ever. Also raised in a thread that such a callback is
    joining (it started the thread, then waits for it in `Thread.join`)."""


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


# ---- reading the caller's values ---------------------------------------------------------
# Every number may be a Python number, a NumPy scalar (np.float64(5), np.int64(5),
# np.float32(0.5)) or a 0-d array; every list any sequence or a NumPy array. NumPy itself is
# not imported for it (duck typing: `.shape == ()` and `.item()`), so `import ratelab` stays
# cheap. A bool is refused as a number.


def _scalar(value: Any) -> Any:
    """A NumPy scalar or 0-d array (anything with `shape == ()` and `item()`) as the Python
    number it holds; anything else as it is."""
    if getattr(value, "shape", None) == () and callable(getattr(value, "item", None)):
        return value.item()
    return value


def _is_bool(value: Any) -> bool:
    return isinstance(value, bool) or (
        type(value).__module__ == "numpy" and type(value).__name__ in ("bool", "bool_")
    )


def _in(unit: str) -> str:
    """`, in Hz,` before the `got …` of a message (`,` without a unit)."""
    return f", in {unit}," if unit else ","


def _real(name: str, value: Any, unit: str = "") -> float:
    """`value` as a float, or SettingTypeError naming `name` and its unit."""
    value = _scalar(value)
    if _is_bool(value) or not isinstance(value, numbers.Real):
        raise SettingTypeError(f"{name} must be a number{_in(unit)} got {value!r}")
    try:
        return float(value)
    except OverflowError:
        raise SettingError(
            f"{name} is too large for a number{_in(unit)} got an int of "
            f"{int(value).bit_length()} bits"
        ) from None


def _whole(name: str, value: Any, unit: str = "", negative_ok: bool = False) -> int:
    """`value` as an int (an int, a NumPy integer: not a float), or an error naming `name`
    and its unit; negative refused here unless `negative_ok` (the native side says the rule
    of a setting it can hold negative, as for every front end)."""
    value = _scalar(value)
    if _is_bool(value) or not isinstance(value, numbers.Integral):
        raise SettingTypeError(f"{name} must be a whole number{_in(unit)} got {value!r}")
    value = int(value)
    if value < 0 and not negative_ok:
        raise SettingError(f"{name} must not be negative{_in(unit)} got {value}")
    return value


def _text(name: str, value: Any, what: str) -> str:
    if not isinstance(value, str):
        raise SettingTypeError(f"{name} must be a str ({what}), got {value!r}")
    return value


def _path(name: str, value: Any) -> str:
    """`value` as a path (a str or os.PathLike): TypeError for any other type, ValueError for
    an empty one (it names no file: a setting's mistake, not the file system's)."""
    try:
        path = os.fspath(value)
    except TypeError:
        raise SettingTypeError(
            f"{name} must be a path (a str or os.PathLike), got {value!r}"
        ) from None
    if not path:
        raise SettingError(f"{name} is an empty path: it names no file or folder")
    return path


def _is_list(value: Any) -> bool:
    """A sequence of values (a list, a tuple, a NumPy array, …), not a text or a mapping."""
    return (
        not isinstance(value, (str, bytes, Mapping))
        and hasattr(value, "__iter__")
        and hasattr(value, "__len__")
        and getattr(value, "shape", None) != ()
    )


def _values(
    name: str, values: Any, read: Callable[[str, Any], Any], empty_ok: bool = False
) -> List[Any]:
    """One value or a sequence of them (a list, a NumPy array, any iterable) as a list, each
    read by `read`; an empty one refused (every check over it would pass without a run)
    unless `empty_ok`."""
    values = _scalar(values)
    if isinstance(values, numbers.Number) or _is_bool(values):
        values = [values]
    elif isinstance(values, (str, bytes, Mapping)) or not hasattr(values, "__iter__"):
        raise SettingTypeError(f"{name} must be a number or a list of numbers, got {values!r}")
    if getattr(values, "ndim", 1) != 1:
        raise SettingTypeError(
            f"{name} must be one number or a one-dimensional list, got an array of shape "
            f"{getattr(values, 'shape', '?')}"
        )
    out = [read(name, v) for v in values]
    if not out and not empty_ok:
        raise SettingError(
            f"{name}: an empty list runs nothing (every check over it would pass without a "
            "run); give at least one value"
        )
    return out


def _number_text(value: Any) -> str:
    """A number as ratelab reads it in text: 10, 0.2, 1e-05 (a whole float without `.0`)."""
    value = _scalar(value)
    if isinstance(value, numbers.Integral) and not _is_bool(value):
        return str(int(value))
    x = float(value)
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def _keyed(name: str, value: Any, what: str) -> List[Tuple[str, Any]]:
    """`{key: v, …}` or `[(key, v), …]` as `[(key, v), …]`, each key a str (`what` says what
    the keys name: node, topic)."""
    if isinstance(value, Mapping):
        items = list(value.items())
    elif _is_list(value):
        items = []
        for item in value:
            if not _is_list(item) or len(item) != 2:
                raise SettingTypeError(
                    f"{name} takes {{{what}: value}} or a list of ({what}, value) pairs, got "
                    f"{item!r}"
                )
            items.append((item[0], item[1]))
    else:
        raise SettingTypeError(f"{name} takes {{{what}: value}}, got {value!r}")
    for key, _ in items:
        if not isinstance(key, str):
            raise SettingTypeError(f"{name}'s keys are {what} names (str), got {key!r}")
    return items


def _pairs_text(name: str, value: Any) -> str:
    """A topic's QoS or link settings as the graph file's `key=value,…` text: given so, or
    as a dict (`{"history": "keep_all", "depth": 100}`)."""
    if isinstance(value, str):
        return value.strip()
    if isinstance(value, Mapping):
        parts = []
        for key, v in value.items():
            v = _scalar(v)
            if _is_bool(v):
                text = "true" if v else "false"
            elif isinstance(v, numbers.Real):
                text = _number_text(v)
            elif isinstance(v, str):
                text = v
            else:
                raise SettingTypeError(f"{name}[{key!r}] must be a number or a str, got {v!r}")
            parts.append(f"{key}={text}")
        return ",".join(parts)
    raise SettingTypeError(
        f"{name} must be 'key=value,…' or a dict of the graph file's keys, got {value!r}"
    )


def _topic_pairs(name: str, value: Any) -> List[Tuple[str, str]]:
    """`qos=`/`link=`: `{"/obs": "history=keep_all"}`, `{"/obs": {"history": "keep_all"}}`,
    or one or a list of `"/obs:history=keep_all"` texts, as `[(topic, "key=value,…")]`."""
    if isinstance(value, str):
        value = [value]
    if _is_list(value) and all(isinstance(v, str) for v in value):
        out = []
        for text in value:
            topic, sep, pairs = text.partition(":")
            if not sep or not topic.strip() or not pairs.strip():
                raise SettingError(
                    f"{name}: expected {{'/topic': 'key=value,…'}} or '/topic:key=value,…', "
                    f"got {text!r}"
                )
            out.append((topic.strip(), pairs.strip()))
        return out
    return [
        (topic, _pairs_text(f"{name}[{topic!r}]", pairs))
        for topic, pairs in _keyed(name, value, "topic")
    ]


def _compute_text(name: str, value: Any) -> str:
    """A compute time, ms: 30, "30", "30±5" or (30, 5) (mean, uniform jitter)."""
    value = _scalar(value)
    if isinstance(value, str):
        return value.strip()
    if _is_list(value) and len(value) == 2:
        mean, jitter = (_real(name, v, "ms") for v in value)
        return f"{_number_text(mean)}±{_number_text(jitter)}"
    return _number_text(_real(name, value, "ms"))


def _stalls(value: Any) -> List[Tuple[str, float, float]]:
    """`stall=`: `{"policy": (2.0, 0.5)}` (at 2 s, for 0.5 s), `{"policy": [(2, 0.5), (5,
    1)]}` or `[("policy", 2.0, 0.5), …]`."""
    rows: List[Tuple[Any, Any]] = []
    if isinstance(value, Mapping):
        for node, spec in value.items():
            many = _is_list(spec) and len(spec) > 0 and all(_is_list(s) for s in spec)
            rows += [(node, s) for s in (spec if many else [spec])]
    elif _is_list(value):
        for entry in value:
            if not _is_list(entry) or len(entry) != 3:
                raise SettingTypeError(
                    "stall takes {node: (at_s, for_s)} or a list of (node, at_s, for_s), got "
                    f"{entry!r}"
                )
            rows.append((entry[0], tuple(entry[1:])))
    else:
        raise SettingTypeError(f"stall takes {{node: (at_s, for_s)}}, got {value!r}")
    out = []
    for node, spec in rows:
        if not isinstance(node, str):
            raise SettingTypeError(f"stall's keys are node names (str), got {node!r}")
        if not _is_list(spec) or len(spec) != 2:
            raise SettingTypeError(f"stall[{node!r}] must be (at_s, for_s), got {spec!r}")
        at_s = _real(f"stall[{node!r}] at_s", spec[0], "s")
        for_s = _real(f"stall[{node!r}] for_s", spec[1], "s")
        out.append((node, at_s, for_s))
    return out


# ---- keywords ----------------------------------------------------------------------------

#: Keywords a function once took or that people try, and what to say about them.
_GONE = {
    "run": {
        "flags": "each of `ratelab run`'s settings is a keyword of run() of its own "
        "(executor=, stall=, compute_ms=, …; help(ratelab.run) lists them)",
    },
    "sweep": {
        "flags": "each of `ratelab sweep`'s settings is a keyword of sweep() of its own "
        "(rate=, stall=, executor=, …; help(ratelab.sweep) lists them)",
    },
    "cliff": {
        "flags": "each of `ratelab cliff`'s settings is a keyword of cliff() of its own "
        "(rate=, stall=, executor=, …; help(ratelab.cliff) lists them)",
    },
    "exercise": {
        "flags": "each of `ratelab exercise`'s graph settings is a keyword of exercise() of "
        "its own (graph=, rate=, qos=, executor=, …; help(ratelab.exercise) lists them)",
        "stall": "an exercise injects its own faults; use ratelab.run(stall=…) for yours",
        "kill": "an exercise injects its own faults; use ratelab.run(kill=…) for yours",
        "clock": "an exercise sets the clock of each of its runs itself",
    },
}


def _keywords(fn: Callable) -> Callable:
    """`fn` refusing an unknown keyword with a `TypeError` (`SettingTypeError`) that names
    the nearest keyword it takes; its signature and docstring stay `fn`'s (help(), an
    editor's completion)."""
    taken = [
        p.name
        for p in inspect.signature(fn).parameters.values()
        if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
    ]
    known = frozenset(taken)

    @functools.wraps(fn)
    def checked(*args: Any, **kwargs: Any) -> Any:
        # IPython (a notebook's traceback) and pytest leave this wrapper's frame out.
        __tracebackhide__ = True  # noqa: F841
        for key in kwargs:
            if key not in known:
                raise SettingTypeError(_unknown_keyword(fn.__name__, key, taken))
        return fn(*args, **kwargs)

    return checked


def _unknown_keyword(function: str, key: str, taken: List[str]) -> str:
    import difflib

    head = f"{function}() got an unexpected keyword argument {key!r}"
    said = _GONE.get(function, {}).get(key)
    if said is not None:
        return f"{head}: {said}"
    near = difflib.get_close_matches(key, taken, n=1, cutoff=0.6)
    if not near:
        folded = key.lower()
        near = [t for t in taken if len(folded) >= 3 and (folded in t or t in folded)][:1]
    if near:
        return f"{head}; did you mean {near[0]!r}?"
    return f"{head} (it takes {', '.join(taken)})"


def _native_call(fn: Callable, *args: Any) -> Any:
    """`_native.fn(*args)`, its refusals as ratelab's exceptions: a bad setting (a plain
    ValueError or TypeError) a `SettingError` or `SettingTypeError`, a trace too large a
    `TraceTooLarge`, an exercise without a prediction a `NoPrediction`."""
    try:
        return fn(*args)
    except _native.TraceTooLarge as e:
        raise TraceTooLarge(str(e)) from None
    except _native.NoPrediction as e:
        raise NoPrediction(str(e)) from None
    except _native.RunInProgress as e:
        raise RunInProgress(str(e)) from None
    except (ValueError, TypeError) as e:
        # The cause, when there is one, is the learner's own exception (a brain file whose
        # import failed), kept with its traceback; else none (the native frame says nothing).
        if type(e) is ValueError:
            raise SettingError(str(e)) from e.__cause__
        if type(e) is TypeError:
            raise SettingTypeError(str(e)) from e.__cause__
        raise  # already of their own kind


# ---- what a run returns --------------------------------------------------------------------


def _g(x: Any) -> str:
    return f"{x:g}" if isinstance(x, (int, float)) and not isinstance(x, bool) else str(x)


def _outcome(metrics: Mapping[str, Any]) -> str:
    """How the run ended, in a few words: balanced 10.0 s, fell at 1.24 s, …"""
    at = metrics.get("sim_time_s")
    at_s = f" at {at:.2f} s" if isinstance(at, (int, float)) else ""
    if metrics.get("node_failed"):
        node = str(metrics["node_failed"]).split(":", 1)[0]
        return f"node {node} failed{at_s}"
    if metrics.get("fell_at_s") is not None:
        return f"fell at {metrics['fell_at_s']:.2f} s"
    if metrics.get("stopped_by_watchdog"):
        return f"stopped by watchdog{at_s}"
    # A fault on the actuator stands the plant still: said, as the summary says it.
    killed_at, lost = _actuator_faults(metrics)
    if killed_at is not None:
        return f"actuator killed at {killed_at:.2f} s"
    if metrics.get("balanced"):
        if lost:
            return f"balanced while the plant ran (the actuator lost {lost} ticks)"
        ran = at if isinstance(at, (int, float)) else metrics.get("duration_s", 0.0)
        return f"balanced {ran:.1f} s"
    return f"not balanced{at_s}"


def _actuator_faults(metrics: Mapping[str, Any]) -> Tuple[Optional[float], int]:
    """The actuator's faults in `metrics["nodes"]`: when it was killed within the run (a
    fault without a duration, at or before `sim_time_s`; None if never) and how many ticks
    faults took from it."""
    ended = metrics.get("sim_time_s")
    for node in (metrics.get("nodes") or {}).values():
        if isinstance(node, dict) and node.get("kind") == "actuator":
            faults = node.get("faults") or []
            kills = [
                f["at_s"] for f in faults
                if "duration_s" not in f and "at_s" in f
                and (not isinstance(ended, (int, float)) or f["at_s"] <= ended)
            ]
            return (min(kills) if kills else None), int(node.get("faulted_ticks") or 0)
    return None, 0


#: The figures `Run`'s HTML table shows, in order, where the metrics have them.
_RUN_FIGURES = (
    "clock", "seed", "duration_s", "graph", "policy", "control_hz", "sensor_hz",
    "queue_depth", "steps", "fell_at_s", "mean_latency_ms", "latency_p99_ms",
    "obs_dropped", "action_dropped",
)


class _Columns:
    """The trace as the run returned it, `(name, dtype, bytes)` per column: what `Run.trace`
    makes its NumPy arrays of when first asked for."""

    def __init__(self, columns: Sequence[Any]):
        self.columns = columns


class _Trace:
    """`Run.trace`, made when first asked for: the run's columns (`_Columns`) become NumPy
    arrays then, and NumPy is imported then, not by `import ratelab` nor by every run
    (importing it costs more than the chapter's run: a fresh process's `ratelab.run()`
    would cost twice `ratelab run`'s). The dataclass's `trace` field, as a data descriptor:
    `Run(trace=…)` takes a dict of arrays as before (or the columns), held in the
    instance's `__dict__` under the field's name. On the class it raises AttributeError,
    so the field has no default, as before."""

    def __get__(self, run: Any, owner: Any = None) -> Dict[str, Any]:
        if run is None:
            raise AttributeError("trace")
        held = run.__dict__["trace"]
        if type(held) is _Columns:
            # Two threads asking at once may each make the arrays (the same values); the
            # later is kept.
            held = run.__dict__["trace"] = _trace_arrays(held.columns)
        return held

    def __set__(self, run: Any, value: Any) -> None:
        # Only the dataclass's __init__ sets it (the instance is frozen).
        run.__dict__["trace"] = value


@dataclass(frozen=True, repr=False, eq=False)
class Run:
    """One run's results, as `ratelab run --out` writes them. Printed, it says how the run
    ended (`<ratelab.Run balanced 10.0 s, control 50 Hz, seed 0, virtual clock>`); in
    Jupyter it is a table of its headline figures.

    Two runs are equal (`==`) when they wrote the same `metrics.json`, `trace.csv` and log,
    byte for byte: under the virtual clock, the same settings and seed give equal runs. The
    wall time and the recording's path are not compared.

    Attributes:
        metrics: `metrics.json` as a dict (docs/metrics.md).
        trace: `trace.csv`'s columns as NumPy arrays, one value per actuator step (with
            `trace_every=N`, per N-th step and the last), named as `TRACE_COLUMNS` says
            (units in the names). Made when first asked for (NumPy is imported then).
        log: `log.txt`'s lines: what the nodes wrote (`print` in a brain or node included),
            stamped `[t=1.234 s node]`.
        summary: The summary `ratelab run` prints (without the wall time).
        recording: The recording written (`record=`), or None.
        metrics_json: `metrics.json`'s exact text.
        trace_csv: `trace.csv`'s exact text.
        wall_s: The wall time the run itself took, s (`ratelab run`'s summary's `wall`).
        estimator: With an estimator in the graph, `estimator.json` as a dict: its RMS error
            per state component (m, m/s, rad, rad/s) and its lag, ms, against the plant's
            true state (docs/metrics.md); None without one.
    """

    metrics: Dict[str, Any]
    trace: Dict[str, Any] = _Trace()
    log: List[str]
    summary: List[str]
    recording: Optional[str]
    metrics_json: str
    trace_csv: str
    wall_s: float
    estimator: Optional[Dict[str, Any]] = None

    def _written(self) -> Tuple[str, str, Tuple[str, ...]]:
        return (self.metrics_json, self.trace_csv, tuple(self.log))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Run):
            return NotImplemented
        return self._written() == other._written()

    def __hash__(self) -> int:
        return hash(self._written())

    @property
    def balanced(self) -> bool:
        """The pole stayed up the whole run (`metrics["balanced"]`)."""
        return bool(self.metrics.get("balanced"))

    def __repr__(self) -> str:
        m = self.metrics
        parts = [_outcome(m)]
        if m.get("control_hz") is not None:
            parts.append(f"control {_g(m['control_hz'])} Hz")
        if m.get("graph") not in (None, "cartpole"):
            parts.append(f"graph {m['graph']}")
        if m.get("seed") is not None:
            parts.append(f"seed {m['seed']}")
        if m.get("clock"):
            parts.append(f"{m['clock']} clock")
        return f"<ratelab.Run {', '.join(parts)}>"

    def _repr_html_(self) -> str:
        from html import escape

        head = self.summary[0] if self.summary else _outcome(self.metrics)
        rows = [
            f"<tr><th style='text-align:left'>{escape(k)}</th>"
            f"<td style='text-align:left'>{escape(_g(self.metrics[k]))}</td></tr>"
            for k in _RUN_FIGURES
            if k in self.metrics and self.metrics[k] is not None
        ]
        return (
            f"<table><caption style='text-align:left'><b>ratelab.Run</b>: "
            f"{escape(_outcome(self.metrics))} &mdash; {escape(head)}</caption>"
            + "".join(rows)
            + "</table>"
        )


class Table:
    """A table of results (`sweep`, `cliff`): `rows` (one dict per row), `columns` (one list
    per column), `csv` (the text `ratelab sweep --csv` writes), `to_pandas()`. In Jupyter it
    is drawn as an HTML table."""

    #: What the table is, for its repr.
    _what = "Table"

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
        """The table as a pandas DataFrame (pandas must be installed: `pip install
        '.[notebooks]'` brings it)."""
        import pandas as pd

        return pd.DataFrame(self.columns)

    def _says(self) -> str:
        return f"{len(self.rows)} rows: {', '.join(self.columns)}"

    def __repr__(self) -> str:
        return f"<ratelab.{self._what} {self._says()}>"

    #: At most this many rows are drawn in Jupyter (`rows` holds them all).
    _HTML_ROWS = 60

    def _repr_html_(self) -> str:
        from html import escape

        def cell(v: Any) -> str:
            return "" if v is None else escape(_g(v))

        head = "".join(f"<th>{escape(n)}</th>" for n in self.columns)
        body = "".join(
            "<tr>" + "".join(f"<td>{cell(r[n])}</td>" for n in self.columns) + "</tr>"
            for r in self.rows[: self._HTML_ROWS]
        )
        more = len(self.rows) - self._HTML_ROWS
        if more > 0:
            body += f"<tr><td colspan='{len(self.columns)}'>… and {more} more rows</td></tr>"
        return (
            f"<table><caption style='text-align:left'><b>ratelab.{self._what}</b>: "
            f"{escape(self._says())}</caption><thead><tr>{head}</tr></thead>"
            f"<tbody>{body}</tbody></table>"
        )


def _span(values: Iterable[Any]) -> str:
    known = sorted({v for v in values if v is not None})
    if not known:
        return "?"
    return _g(known[0]) if len(known) == 1 else f"{_g(known[0])}–{_g(known[-1])}"


class Sweep(Table):
    """`sweep`'s table, a row per run (the columns `ratelab sweep --csv` writes). Printed, it
    says how many runs balanced and how many fell."""

    _what = "Sweep"

    def _says(self) -> str:
        n = len(self.rows)
        balanced = sum(1 for r in self.rows if r.get("balanced") is True)
        fell = sum(1 for r in self.rows if r.get("fell_at_s") is not None)
        said = f"{n} run{'' if n == 1 else 's'}: {balanced} balanced, {fell} fell"
        other = n - balanced - fell
        if other > 0:
            said += f", {other} neither (a node failed or the run stopped)"
        if n:
            said += (
                f"; control {_span(r.get('control_hz') for r in self.rows)} Hz, "
                f"seeds {_span(r.get('seed') for r in self.rows)}"
            )
        return said


class Cliff(Table):
    """`cliff`'s table, a row per seed: `seed`, `falls_at_hz` (the highest control rate at
    which the pole falls), `balances_at_hz` (the next rate up; None when there is none),
    `runs`. Printed, it says where each seed falls."""

    _what = "Cliff"

    def _says(self) -> str:
        said = []
        for r in self.rows[:3]:
            falls, balances = r.get("falls_at_hz"), r.get("balances_at_hz")
            said.append(
                f"seed {r.get('seed')}: "
                + (f"falls at {_g(falls)} Hz" if falls is not None else "no fall found")
                + ", "
                + (f"balances at {_g(balances)} Hz" if balances is not None
                   else "no balance found")
            )
        if len(self.rows) > 3:
            said.append(f"… ({len(self.rows)} seeds)")
        return "; ".join(said) if said else "no seeds"


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


class NodeFailed(Error, RuntimeError):
    """A node of the run failed (a brain or node raised): the message is ratelab's line,
    `.run` the run's figures up to the failure (None for a sweep's). When Python code
    failed it (`ratelab.run`), its own exception, with its traceback, is `__cause__`:
    `%debug` or `pdb.post_mortem(e.__cause__.__traceback__)` go into the node's frame."""

    def __init__(self, message: str, run: Optional[Run]):
        super().__init__(message)
        self.run = run


def _trace_arrays(columns: Sequence[Any]) -> Dict[str, Any]:
    """`(name, dtype, bytes)` per column (made from trace.csv's text) as NumPy arrays."""
    import numpy as np

    return {TRACE_COLUMNS.get(n, n): np.frombuffer(b, dtype=k) for n, k, b in columns}


# ---- the settings run, sweep and cliff share ---------------------------------------------------


def _graph_settings(
    graph: Any,
    rate: Any,
    depth: Any,
    qos: Any,
    link: Any,
    lease_ms: Any,
    stall: Any,
    kill: Any,
    compute_ms: Any,
    executor: Any,
    phase_offset_ms: Any,
) -> Dict[str, Any]:
    """The graph and its overrides as `_native`'s settings (a key each, left out when not
    given; see `run` for what each takes), every value read here into its type."""
    settings: Dict[str, Any] = {}
    if graph is not None:
        settings["graph"] = _path("graph", graph)
    lists: Dict[str, List[Any]] = {}
    if rate is not None:
        lists["rate"] = [
            (n, _real(f"rate[{n!r}]", hz, "Hz")) for n, hz in _keyed("rate", rate, "node")
        ]
    if depth is not None:
        lists["depth"] = [
            (t, _whole(f"depth[{t!r}]", d, "messages"))
            for t, d in _keyed("depth", depth, "topic")
        ]
    if qos is not None:
        lists["qos"] = _topic_pairs("qos", qos)
    if link is not None:
        lists["link"] = _topic_pairs("link", link)
    if lease_ms is not None:
        lists["lease_ms"] = [
            (n, _real(f"lease_ms[{n!r}]", ms, "ms"))
            for n, ms in _keyed("lease_ms", lease_ms, "node")
        ]
    if stall is not None:
        lists["stall"] = _stalls(stall)
    if kill is not None:
        lists["kill"] = [
            (n, _real(f"kill[{n!r}]", at, "s")) for n, at in _keyed("kill", kill, "node")
        ]
    if compute_ms is not None:
        lists["compute_ms"] = [
            (n, _compute_text(f"compute_ms[{n!r}]", ms))
            for n, ms in _keyed("compute_ms", compute_ms, "node")
        ]
    if phase_offset_ms is not None:
        lists["phase_offset_ms"] = _values(
            "phase_offset_ms", phase_offset_ms, lambda n, v: _real(n, v, "ms"), empty_ok=True
        )
    settings.update((k, v) for k, v in lists.items() if v)
    if executor is not None:
        settings["executor"] = _text(
            "executor", executor, '"single_threaded", "multi_threaded:N" or "per_node"'
        )
    return settings


def _brain(settings: Dict[str, Any], policy: Any) -> Optional[Callable[[Any], Any]]:
    """`policy=`: a callable brain, returned (it runs in this interpreter); else a name or a
    file, put in `settings` (None: the default, the scripted balancer)."""
    if callable(policy):
        _takes("policy", policy, "a brain is called with one argument, the observation "
               "(act(obs) -> action)")
        return policy
    if policy is not None:
        settings["policy"] = _path("policy", policy)
    return None


def _takes(name: str, fn: Callable, contract: str) -> None:
    """Refuse `fn` (given as `name`) up front when it cannot be called with one argument, as
    the run will call it: the error names the parameter and your function's own signature,
    not a line inside ratelab. One without a signature Python can read is judged when called."""
    try:
        sig = inspect.signature(fn)
    except Exception:  # no signature Python can read (a builtin; annotations it cannot resolve)
        return
    try:
        sig.bind(None)
    except TypeError:
        what = getattr(fn, "__name__", type(fn).__name__)
        raise SettingTypeError(f"{name}: {contract}; {what}{sig} cannot take it") from None


# ---- run -------------------------------------------------------------------------------------


@_keywords
def run(
    graph: Optional[PathLike] = None,
    *,
    clock: Optional[str] = None,
    seed: Optional[int] = None,
    duration_s: Optional[float] = None,
    control_hz: Optional[float] = None,
    sensor_hz: Optional[float] = None,
    queue_depth: Optional[int] = None,
    rate: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    depth: Union[None, Mapping[str, int], Sequence[Tuple[str, int]]] = None,
    qos: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    link: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    lease_ms: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    stall: Union[
        None, Mapping[str, Tuple[float, float]], Sequence[Tuple[str, float, float]]
    ] = None,
    kill: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    compute_ms: Union[None, Mapping[str, Union[float, str, Tuple[float, float]]]] = None,
    executor: Optional[str] = None,
    phase_offset_ms: Optional[Sequence[float]] = None,
    policy: Union[None, str, PathLike, Callable[[Any], Any]] = None,
    record: Optional[PathLike] = None,
    out: Optional[PathLike] = None,
    force: bool = False,
    nodes: Optional[Mapping[str, type]] = None,
    trace_every: Optional[int] = None,
) -> Run:
    """Run a graph, as `ratelab run` does, and return its figures. A setting left out (None)
    is `ratelab run`'s default: the same defaults for every front end. Calls from several
    threads run one after another (a run's log and its Python output are the process's
    while it goes); `sweep` and `cliff` spread their runs over the cores themselves. A run
    started from inside a run's brain or node raises `RunInProgress` (a RuntimeError).

    >>> import ratelab
    >>> run = ratelab.run(clock="virtual", duration_s=1)
    >>> run
    <ratelab.Run balanced 1.0 s, control 50 Hz, seed 0, virtual clock>
    >>> run.metrics["steps"], run.trace["pole_angle_rad"].dtype
    (51, dtype('float64'))
    >>> import numpy as np
    >>> ratelab.run(clock="virtual", duration_s=np.float64(2), control_hz=np.int64(25),
    ...             compute_ms={"policy": (30, 5)}, executor="single_threaded",
    ...             stall={"policy": (0.5, 0.2)}, phase_offset_ms=np.array([0, 5, 10]))
    <ratelab.Run ..., control 25 Hz, seed 0, virtual clock>

    graph: a graph file (default the chapter's: sensor -> /obs -> policy -> /action ->
        actuator).
    clock: "real" (the default, as `ratelab run`'s: node threads against the monotonic
        clock, not reproducible) or "virtual" (deterministic: same settings, same bytes).
    seed: the reset seed (default 0). duration_s: run time, s (default 10).
    control_hz, sensor_hz (Hz), queue_depth (messages): the chapter's three knobs (default:
        the graph's).
    rate: per-node rates, Hz ({"policy": 10}). depth: per-topic history depths, messages
        ({"/obs": 100}).
    qos: per-topic QoS, with the graph file's keys ({"/obs": {"history": "keep_all",
        "depth": 100}}, {"/obs": "history=keep_all,depth=100"}, or ["/obs:history=keep_all"]).
    link: per-topic lossy links ({"/action": {"loss": 0.2, "delay_ms": 10}}, same forms).
    lease_ms: per-node liveliness leases, ms ({"policy": 100}).
    stall: per-node stalls, s: {"policy": (2.0, 0.5)} stalls it at 2 s for 0.5 s (several:
        {"policy": [(2, 0.5), (5, 1)]}, or [("policy", 2.0, 0.5), …]).
    kill: per-node kills, s of run time ({"policy": 3.0}).
    compute_ms: per-node compute time of a tick, ms ({"policy": 30}; with uniform jitter
        {"policy": (30, 5)} or {"policy": "30±5"}).
    executor: every node but the actuator (which steps the plant, on a thread of its
        own) on one executor: "single_threaded", "multi_threaded:N" or "per_node"
        (replaces the graph file's [executors]).
    phase_offset_ms: first-tick offsets, ms, one per node in tie-break order ([0, 5, 10],
        or a NumPy array).
    policy: the brain: "scripted" (default), a checkpoint path, "FILE.py[:FUNCTION]", or a
        callable `f(obs) -> action` (obs a NumPy float32[5]; action a float in [-1, 1]).
        What a brain or node prints goes to the run's log (`run.log`, log.txt), not to
        this terminal, as a node's output does in a launch.
    record: write a rerun recording to this path. out: also write metrics.json, trace.csv
        and log.txt to this folder (force: replace existing files).
    nodes: classes for the graph's Python nodes, by node name ({"policy": MyNode}): each
        is made from the class given (defined here, in a notebook cell) instead of its
        graph file's script, and driven exactly as one from a file. A name the graph has no
        Python node of is refused.
    trace_every: keep one actuator step in this many in `Run.trace` (steps 1, 1 + N, ... and
        the last; default 1): a long run's trace in proportion to what you ask. The metrics
        count every step.

    Numbers may be NumPy scalars and lists NumPy arrays. An unknown keyword raises
    SettingTypeError (a TypeError) naming the nearest one; a bad value SettingError (a
    ValueError) naming the parameter. Also raises FileNotFoundError, FileExistsError,
    IsADirectoryError (`record=` a folder), OSError (an output the file system refuses),
    NodeFailed, KeyboardInterrupt, and TraceTooLarge (a MemoryError) before a run whose
    trace would not fit in memory.
    """
    settings = _graph_settings(
        graph, rate, depth, qos, link, lease_ms, stall, kill, compute_ms, executor,
        phase_offset_ms,
    )
    if clock is not None:
        settings["clock"] = _text("clock", clock, '"real" or "virtual"')
    if seed is not None:
        settings["seed"] = _whole("seed", seed, negative_ok=True)
    if duration_s is not None:
        settings["duration_s"] = _real("duration_s", duration_s, "s")
    if control_hz is not None:
        settings["control_hz"] = _real("control_hz", control_hz, "Hz")
    if sensor_hz is not None:
        settings["sensor_hz"] = _real("sensor_hz", sensor_hz, "Hz")
    if queue_depth is not None:
        settings["queue_depth"] = _whole("queue_depth", queue_depth, "messages", negative_ok=True)
    brain = _brain(settings, policy)
    if record is not None:
        settings["record"] = _path("record", record)
    if out is not None:
        settings["out"] = _path("out", out)
    if force:
        if not _is_bool(force):
            raise SettingTypeError(f"force must be True or False, got {force!r}")
        settings["force"] = True
    if trace_every is not None:
        settings["trace_every"] = _whole("trace_every", trace_every, "steps", negative_ok=True)
    classes = []
    if nodes is not None:
        for node, cls in _keyed("nodes", nodes, "node"):
            if not isinstance(cls, type):
                raise SettingTypeError(
                    f"nodes[{node!r}] must be a class, got {type(cls).__name__}"
                )
            _takes(f"nodes[{node!r}]", cls,
                   "a node class is made with one argument, its node handle "
                   "(def __init__(self, node))")
            classes.append((node, cls))
    files = _native_call(_native.run, settings, brain, classes)
    result = Run(
        metrics=json.loads(files["metrics_json"]),
        trace=_Columns(files["trace_columns"]),  # NumPy arrays when first asked for
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
    for line in files["warnings"]:
        # A fault set after the run ends does nothing: said where the caller's line is.
        warnings.warn(line.removeprefix("warning: "), RuntimeWarning, stacklevel=3)
    if files["failed"] is not None:
        cause = files.get("failed_exception")
        if cause is not None:
            # The node's own exception, its traceback included: what to debug into.
            raise NodeFailed(files["failed"], result) from cause
        raise NodeFailed(files["failed"], result)
    return result


# ---- sweep, cliff ----------------------------------------------------------------------------
# The settings every run shares go as `run`'s do (a dict of the keywords); the grid's lists
# and the search's range in a dict of their own. Every rule is the library's (an empty list
# refused among them), in Python's words.


def _reals(name: str, values: Any, unit: str) -> List[float]:
    return _values(name, values, lambda n, v: _real(n, v, unit), empty_ok=True)


def _wholes(name: str, values: Any, unit: str = "") -> List[int]:
    return _values(name, values, lambda n, v: _whole(n, v, unit), empty_ok=True)


def _clocks(value: Any) -> List[str]:
    """`clock=`: "virtual", "real", or a list of them."""
    what = '"real" or "virtual"'
    if isinstance(value, str):
        return [value]
    if not _is_list(value):
        raise SettingTypeError(f"clock must be {what} or a list of them, got {value!r}")
    return [_text("clock", c, what) for c in value]


@_keywords
def sweep(
    graph: Optional[PathLike] = None,
    *,
    control_hz: Union[float, Sequence[float]] = (50, 25, 20, 15, 10, 5),
    sensor_hz: Union[float, Sequence[float]] = 50,
    queue_depth: Union[int, Sequence[int]] = 1,
    seeds: Union[int, Sequence[int]] = (0, 1, 2),
    clock: Union[str, Sequence[str]] = "virtual",
    policy: Union[str, PathLike, Callable[[Any], Any]] = "scripted",
    duration_s: float = 10.0,
    rate: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    depth: Union[None, Mapping[str, int], Sequence[Tuple[str, int]]] = None,
    qos: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    link: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    lease_ms: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    stall: Union[
        None, Mapping[str, Tuple[float, float]], Sequence[Tuple[str, float, float]]
    ] = None,
    kill: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    compute_ms: Union[None, Mapping[str, Union[float, str, Tuple[float, float]]]] = None,
    executor: Optional[str] = None,
    phase_offset_ms: Optional[Sequence[float]] = None,
) -> Sweep:
    """Every combination of the given rates, depths, seeds and clocks, one run each, on every
    core (as `ratelab sweep`): a `Sweep` table with a row per run (its point and figures: the
    columns `ratelab sweep --csv` writes). Each of control_hz (Hz), sensor_hz (Hz),
    queue_depth (messages), seeds and clock ("virtual", "real") is one value or a list (a
    NumPy array too); an empty list is refused. A run that failed a node raises NodeFailed
    once all have run (its `.run` is None).

    >>> import ratelab
    >>> table = ratelab.sweep(control_hz=[50, 5], seeds=[0], duration_s=2)
    >>> table
    <ratelab.Sweep 2 runs: 1 balanced, 1 fell; control 5–50 Hz, seeds 0>
    >>> sorted((row["control_hz"], row["balanced"]) for row in table)
    [(5, False), (50, True)]

    The brain may be a function defined here, as for `run`: the scripted balancer's
    arithmetic in Python gives the built-in's figures.

    >>> import math
    >>> def act(obs):
    ...     theta = math.atan2(float(obs[3]), float(obs[2]))
    ...     return 10 * theta + 2 * float(obs[4]) + 0.4 * float(obs[0]) + 0.8 * float(obs[1])
    >>> mine = ratelab.sweep(policy=act, control_hz=[50, 5], seeds=[0], duration_s=2)
    >>> [row["fell_at_s"] for row in mine] == [row["fell_at_s"] for row in table]
    True

    policy: the brain of every run: "scripted" (default), a checkpoint path,
        "FILE.py[:FUNCTION]", or a callable `f(obs) -> action` (as `run`'s). A callable is
        called in this interpreter, a call at a time (under the GIL) though the runs go on
        every core; the one function is every run's, so it should keep no state between
        calls (a file's brain is loaded afresh for each run).
    duration_s: each run's length, s (default 10). graph, rate, depth, qos, link, lease_ms,
        stall, kill, compute_ms, executor, phase_offset_ms: the graph and its overrides, as
        `run` takes them (the grid sets the chain's sensor and control rates and every
        topic's depth; a `rate` of the sensor or the policy is refused beside it).

    An unknown keyword raises SettingTypeError (a TypeError) naming the nearest one; a bad
    value SettingError (a ValueError) naming the parameter (`seeds: an empty list runs
    nothing …`). Also raises FileNotFoundError, NodeFailed, KeyboardInterrupt.
    """
    settings = _graph_settings(
        graph, rate, depth, qos, link, lease_ms, stall, kill, compute_ms, executor,
        phase_offset_ms,
    )
    settings["duration_s"] = _real("duration_s", duration_s, "s")
    brain = _brain(settings, policy)
    grid: Dict[str, Any] = {
        "control_hz": _reals("control_hz", control_hz, "Hz"),
        "sensor_hz": _reals("sensor_hz", sensor_hz, "Hz"),
        "queue_depth": _wholes("queue_depth", queue_depth, "messages"),
        "seeds": _wholes("seeds", seeds),
        "clock": _clocks(clock),
    }
    text, failed = _native_call(_native.sweep, settings, grid, brain)
    table = Sweep(text)
    if failed is not None:
        raise NodeFailed(failed, None)
    return table


@_keywords
def cliff(
    graph: Optional[PathLike] = None,
    *,
    seeds: Union[int, Sequence[int]] = (0, 1, 2),
    sensor_hz: float = 50,
    queue_depth: int = 1,
    min_hz: float = 1,
    max_hz: float = 50,
    step_hz: float = 0.1,
    policy: Union[str, PathLike, Callable[[Any], Any]] = "scripted",
    duration_s: float = 10.0,
    rate: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    depth: Union[None, Mapping[str, int], Sequence[Tuple[str, int]]] = None,
    qos: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    link: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    lease_ms: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    stall: Union[
        None, Mapping[str, Tuple[float, float]], Sequence[Tuple[str, float, float]]
    ] = None,
    kill: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    compute_ms: Union[None, Mapping[str, Union[float, str, Tuple[float, float]]]] = None,
    executor: Optional[str] = None,
    phase_offset_ms: Optional[Sequence[float]] = None,
) -> Cliff:
    """Per seed, the highest control rate at which the pole falls within `duration_s`, to
    `step_hz` (as `ratelab cliff`; virtual clock): a `Cliff` table with the columns seed,
    falls_at_hz, balances_at_hz (None when there is none) and runs.

    >>> import ratelab
    >>> table = ratelab.cliff(seeds=[0], min_hz=4, max_hz=12, step_hz=0.5)
    >>> table
    <ratelab.Cliff seed 0: falls at ... Hz, balances at ... Hz>
    >>> row = table.rows[0]
    >>> row["balances_at_hz"] - row["falls_at_hz"]
    0.5

    seeds: one or a list (a NumPy array too), not empty. sensor_hz (Hz), queue_depth
        (messages): the chain's sensor rate and every topic's depth in every run.
    min_hz, max_hz, step_hz: the control rates searched, Hz: from max_hz down by step_hz
        to min_hz (at most 5000 rates), until the first fall.
    policy: the brain, as `sweep`'s (a callable too: seeds go on every core, its calls
        one at a time). duration_s, graph and its overrides: as `sweep`'s (a `rate` of the
        policy is refused: the search sets it).

    An unknown keyword raises SettingTypeError (a TypeError) naming the nearest one; a bad
    value SettingError (a ValueError) naming the parameter (`min_hz (20) must not be above
    max_hz (10)`). A brain that raised stops the search with a ValueError naming the seed,
    the rate and the exception (such a run neither balanced nor fell). Also raises
    FileNotFoundError, KeyboardInterrupt.
    """
    settings = _graph_settings(
        graph, rate, depth, qos, link, lease_ms, stall, kill, compute_ms, executor,
        phase_offset_ms,
    )
    settings["duration_s"] = _real("duration_s", duration_s, "s")
    settings["sensor_hz"] = _real("sensor_hz", sensor_hz, "Hz")
    settings["queue_depth"] = _whole("queue_depth", queue_depth, "messages", negative_ok=True)
    brain = _brain(settings, policy)
    search = {
        "seeds": _wholes("seeds", seeds),
        "min_hz": _real("min_hz", min_hz, "Hz"),
        "max_hz": _real("max_hz", max_hz, "Hz"),
        "step_hz": _real("step_hz", step_hz, "Hz"),
    }
    return Cliff(_native_call(_native.cliff, settings, search, brain))


@dataclass(frozen=True)
class Check:
    """One of an exercise's checks: what was checked, and whether it held."""

    name: str
    passed: bool


@dataclass(frozen=True)
class Prediction:
    """One key of the learner's prediction beside the outcome: the key, the sentence saying
    both ("You predicted the pole first fails at 10 Hz; it first fell at 5 Hz."), and the
    verdict: "right", "missed", "unreadable" (not of the type the exercise reads) or "open" (not
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


@_keywords
def exercise(
    which: str,
    prediction: Optional[Mapping[str, Any]] = None,
    *,
    dir: PathLike = "exercises",
    graph: Optional[PathLike] = None,
    rate: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    depth: Union[None, Mapping[str, int], Sequence[Tuple[str, int]]] = None,
    qos: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    link: Union[None, str, Mapping[str, Union[str, Mapping[str, Any]]], Sequence[str]] = None,
    lease_ms: Union[None, Mapping[str, float], Sequence[Tuple[str, float]]] = None,
    compute_ms: Union[None, Mapping[str, Union[float, str, Tuple[float, float]]]] = None,
    executor: Optional[str] = None,
) -> Exercise:
    """Run exercise `which` ("ex1", …) as `ratelab exercise` does, with `prediction` (the keys
    its file's [prediction] asks for, and "why") in place of the learner's file's when given.

    dir: the folder of the exercise files and bands.toml (outside a clone of the
    repository, `copy_exercises` makes one). graph: the graph to run it on
    (default: the exercise's own, as its bands name it). rate, depth, qos, link, lease_ms,
    compute_ms, executor: the graph's overrides, as `run` takes them. An exercise injects
    its own faults and sets its own clock and the chain's rates (control_hz, sensor_hz,
    queue_depth), so `stall`, `kill`, `clock` and those are not settings of it.

    Raises NoPrediction (a ValueError) when there is no prediction yet, SettingTypeError (a
    TypeError) for an unknown keyword, ValueError for an unknown exercise or bad input,
    FileNotFoundError for a missing folder or file. Ctrl-C ends the run in progress and
    raises KeyboardInterrupt, nothing graded.
    """
    settings = _graph_settings(
        graph, rate, depth, qos, link, lease_ms, None, None, compute_ms, executor, None
    )
    settings["dir"] = _path("dir", dir)
    given = None if prediction is None else json.dumps(dict(prediction))
    found = _native_call(_native.exercise, _text("which", which, '"ex1", …'), settings, given)
    return Exercise(
        checks=[Check(name, passed) for name, passed in found["checks"]],
        reconcile=list(found["reconcile"]),
        not_passed=int(found["not_passed"]),
        report=list(found["lines"]),
        predictions=[Prediction(k, said, v) for k, said, v in found["predictions"]],
    )


def copy_exercises(to: PathLike = ".", *, force: bool = False) -> str:
    """Copy the exercises and the graphs they run on, which the package carries, into the
    folder `to` (as `to/exercises` and `to/graphs`, made if missing), so that they run and
    can be edited outside a clone of the repository (ex6 asks for a node of your own, ex11
    for a brain). Returns the exercises folder, for `exercise`'s `dir`:

        folder = ratelab.copy_exercises("my-lab")
        ratelab.exercise("ex1", {"fails_at_hz": 5, "why": "..."}, dir=folder)

    Raises FileExistsError, copying nothing, when `to/exercises` or `to/graphs` exists and
    `force` is not set (force=True replaces them); FileNotFoundError when this install
    carries no exercises (an editable install, or one built from an sdist: use the clone's
    `exercises/`).
    """
    import shutil

    target = _path("to", to)
    lab = os.path.join(os.path.dirname(os.path.abspath(__file__)), "_lab")
    if not os.path.isdir(os.path.join(lab, "exercises")):
        raise FileNotFoundError(
            "this install of ratelab carries no exercises (an editable install, or one "
            "built from an sdist): use the exercises/ folder of the repository"
        )
    folders = ("exercises", "graphs")
    there = [f for f in folders if os.path.lexists(os.path.join(target, f))]
    if there and not force:
        names = " and ".join(os.path.join(target, f) for f in there)
        raise FileExistsError(f"{names} already exist: pass force=True to replace them")
    for f in folders:
        dest = os.path.join(target, f)
        if os.path.isdir(dest) and not os.path.islink(dest):
            shutil.rmtree(dest)
        elif os.path.lexists(dest):
            os.remove(dest)
        shutil.copytree(os.path.join(lab, f), dest)
    return os.path.join(target, "exercises")


def exercises() -> List[Dict[str, str]]:
    """The exercises, in order: their `id` ("ex1"), `file` in the exercises folder
    ("ex1_rate_cliff.toml") and `title`.

    >>> import ratelab
    >>> ratelab.exercises()[0]["id"], ratelab.exercises()[0]["file"]
    ('ex1', 'ex1_rate_cliff.toml')
    """
    return [{"id": i, "file": f, "title": t} for i, f, t in _native.exercises()]
