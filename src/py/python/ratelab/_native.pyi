"""Stubs of ratelab's extension module (src/py/lib.rs); use the `ratelab` package."""

from typing import Any, Callable, Dict, List, Optional, Tuple

__version__: str

def main(argv: List[str]) -> int:
    """ratelab's command line on `argv` (the program's name first); returns the exit code."""

def run(
    settings: Dict[str, Any],
    policy: Optional[Callable[[Any], Any]] = None,
    nodes: List[Tuple[str, type]] = [],
) -> Dict[str, Any]:
    """One run of the settings given, each key optional (left out: `ratelab run`'s default):
    graph (str), clock ("real" | "virtual"), seed (int), duration_s, control_hz, sensor_hz
    (float), queue_depth (int), rate [(node, hz)], depth [(topic, n)], qos [(topic,
    "key=value,...")], link [(topic, "key=value,...")], lease_ms [(node, ms)], stall [(node,
    at_s, for_s)], kill [(node, at_s)], compute_ms [(node, "30" | "30±5")], executor (str),
    phase_offset_ms [float], policy (str), record (str), out (str), force (bool),
    trace_every (int); `policy` a callable brain, `nodes` (node, class) pairs for the graph's
    Python nodes. Returns metrics_json, trace_csv, log (texts), summary (lines), failed (a
    node's failure line or None), recording (path or None), wall_s, trace_columns ((name,
    numpy dtype, bytes) per column of trace_csv), estimator_json (estimator.json's text with
    an estimator in the graph, else None). Raises ValueError naming the Python parameter,
    and TraceTooLarge before the run when its trace would pass MAX_HELD_TRACE_VALUES."""

def sweep(
    settings: Dict[str, Any],
    grid: Dict[str, Any],
    brain: Optional[Callable[[Any], Any]] = None,
) -> Tuple[str, Optional[str]]:
    """A sweep: `settings` what every run shares (run's keys graph, duration_s, rate, depth,
    qos, link, lease_ms, stall, kill, compute_ms, executor, phase_offset_ms, policy), `grid`
    its lists (clock [str], sensor_hz [float], control_hz [float], queue_depth [int], seeds
    [int]), `brain` a callable brain for every run. Returns (its `ratelab sweep --csv` text,
    the first failed node's line or None). Raises ValueError naming the Python parameter."""

def cliff(
    settings: Dict[str, Any],
    search: Dict[str, Any],
    brain: Optional[Callable[[Any], Any]] = None,
) -> str:
    """A cliff search: `settings` what every run shares (sweep's keys, and sensor_hz,
    queue_depth), `search` seeds [int], min_hz, max_hz, step_hz (float), `brain` a callable
    brain for every run. Returns CSV seed,falls_at_hz,balances_at_hz,runs."""

class NoPrediction(ValueError):
    """An exercise was asked for before its prediction was written."""

class TraceTooLarge(MemoryError):
    """A run whose trace, returned in memory, would pass MAX_HELD_TRACE_VALUES: refused
    before it starts."""

def exercise(
    which: str, settings: Dict[str, Any], prediction_json: Optional[str] = None
) -> Dict[str, Any]:
    """Exercise `which` with `settings` (`dir`, `graph` and the graph's overrides, as
    `ratelab.exercise` reads them): checks [(name, passed)], reconcile [sentence],
    predictions [(key, sentence, verdict)], counts and lines."""


def exercises() -> List[Tuple[str, str, str]]:
    """The exercises in order: (id, file, title)."""

def install_messages() -> None:
    """Put the message classes (State, Position, Force, ...) and Time into `ratelab`."""
