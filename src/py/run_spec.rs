//! `ratelab.run`'s settings (a dict keyed by its keywords, made by the package's Python
//! side) as the library's [`RunSpec`]: Python's half of a run's set-up; and `ratelab.sweep`'s
//! and `ratelab.cliff`'s, the same dict for what every run shares and one more for the grid
//! or the search, as the library's [`SweepSpec`] and [`CliffSpec`]. Every rule of the values
//! is the library's ([`RunSpec::config`], [`SweepSpec::grid`], [`CliffSpec::config`]); here
//! only their types are read, and a wrong type is a `TypeError` naming the keyword.
//!
//! The keys of a run's settings, each optional (left out: `ratelab run`'s default):
//! `graph` (str), `clock` ("real" | "virtual"), `seed` (int ≥ 0), `duration_s`,
//! `control_hz`, `sensor_hz` (float), `queue_depth` (int), `rate` ([(node, hz)]),
//! `depth` ([(topic, n)]), `qos`, `link` ([(topic, "key=value,…")]), `lease_ms`
//! ([(node, ms)]), `stall` ([(node, at_s, for_s)]), `kill` ([(node, at_s)]), `compute_ms`
//! ([(node, "30" | "30±5")]), `executor` (str), `phase_offset_ms` ([float]), `policy`
//! (str), `record`, `out` (str), `force` (bool), `trace_every` (int ≥ 1). A sweep's and a
//! search's take those of [`SHARED_KEYS`] (a search's `sensor_hz` and `queue_depth` too); a
//! grid's keys are `clock` ([str]), `sensor_hz`, `control_hz` ([float]), `queue_depth`,
//! `seeds` ([int]), a search's `seeds` ([int]), `min_hz`, `max_hz`, `step_hz` (float).

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use ratelab::config::ClockKind;
use ratelab::executor::{ComputeTime, ExecutorOverride};
use ratelab::qos::Fault;
use ratelab::run_spec::RunSpec;
use ratelab::sweep_spec::{CliffSpec, SweepSpec};
use ratelab::time::{Nanos, MAX_DURATION_S};
use ratelab_exercises::ExerciseSpec;
use std::path::PathBuf;

/// Every key [`from_settings`] reads.
pub const KEYS: [&str; 22] = [
    "graph",
    "clock",
    "seed",
    "duration_s",
    "control_hz",
    "sensor_hz",
    "queue_depth",
    "rate",
    "depth",
    "qos",
    "link",
    "lease_ms",
    "stall",
    "kill",
    "compute_ms",
    "executor",
    "phase_offset_ms",
    "policy",
    "record",
    "out",
    "force",
    "trace_every",
];

/// The keys of a run's settings a sweep's and a cliff search's take: what every one of their
/// runs shares (the seed, clock and chain's rates are the grid's or the search's; nothing
/// is written).
pub const SHARED_KEYS: [&str; 13] = [
    "graph",
    "duration_s",
    "rate",
    "depth",
    "qos",
    "link",
    "lease_ms",
    "stall",
    "kill",
    "compute_ms",
    "executor",
    "phase_offset_ms",
    "policy",
];

/// A cliff search's shared keys: [`SHARED_KEYS`], and the sensor's rate and queue depth it
/// keeps for every run.
const CLIFF_KEYS: [&str; SHARED_KEYS.len() + 2] = {
    let mut keys = [""; SHARED_KEYS.len() + 2];
    let mut i = 0;
    while i < SHARED_KEYS.len() {
        keys[i] = SHARED_KEYS[i];
        i += 1;
    }
    keys[i] = "sensor_hz";
    keys[i + 1] = "queue_depth";
    keys
};

/// `ratelab.exercise`'s keys ([`exercise_from`]): its folder and the graph's settings, no
/// faults (an exercise injects its own) and none of a run's own (an exercise sets them).
pub const EXERCISE_KEYS: [&str; 9] = [
    "dir",
    "graph",
    "rate",
    "depth",
    "qos",
    "link",
    "lease_ms",
    "compute_ms",
    "executor",
];

/// A grid's keys ([`sweep_from`]).
const GRID_KEYS: [&str; 5] = ["clock", "sensor_hz", "control_hz", "queue_depth", "seeds"];

/// A search's keys ([`cliff_from`]).
const SEARCH_KEYS: [&str; 4] = ["seeds", "min_hz", "max_hz", "step_hz"];

/// Refuse a key of `settings` not among `keys`: a `TypeError` naming it, `function` and the
/// keys it takes.
fn known_keys(settings: &Bound<'_, PyDict>, function: &str, keys: &[&str]) -> PyResult<()> {
    for key in settings.keys() {
        let key: String = key.extract()?;
        if !keys.contains(&key.as_str()) {
            return Err(PyTypeError::new_err(format!(
                "{function}() got an unexpected setting '{key}' (settings: {})",
                keys.join(", ")
            )));
        }
    }
    Ok(())
}

/// The value of `key` in `settings`, read as `T`; `None` when it is left out or None.
///
/// # Errors
/// `TypeError` naming the key and the type it takes (`what`).
fn get<'py, T: pyo3::conversion::FromPyObjectOwned<'py>>(
    settings: &Bound<'py, PyDict>,
    key: &str,
    what: &str,
) -> PyResult<Option<T>> {
    match settings.get_item(key)? {
        None => Ok(None),
        Some(v) if v.is_none() => Ok(None),
        Some(v) => v.extract::<T>().map(Some).map_err(|e| {
            // A whole number past what the setting can hold (2**64 as a depth): its range,
            // not its type, is wrong.
            let e: pyo3::PyErr = e.into();
            if e.is_instance_of::<pyo3::exceptions::PyOverflowError>(v.py()) {
                return PyValueError::new_err(format!(
                    "{key} takes {what}: a number of it is out of range"
                ));
            }
            let got = v
                .get_type()
                .name()
                .map_or_else(|_| "?".to_string(), |n| n.to_string());
            PyTypeError::new_err(format!("{key} takes {what}, got {got}"))
        }),
    }
}

/// A time of a fault, s, as a [`Nanos`].
///
/// # Errors
/// `ValueError` naming the key, outside [0, [`MAX_DURATION_S`]].
fn fault_time(key: &str, node: &str, secs: f64) -> PyResult<Nanos> {
    (secs.is_finite() && (0.0..=MAX_DURATION_S).contains(&secs))
        .then(|| Nanos::from_secs_f64(secs))
        .flatten()
        .ok_or_else(|| {
            PyValueError::new_err(format!(
                "{key}[{node:?}]: a time is in [0, {MAX_DURATION_S}] s, got {secs}"
            ))
        })
}

/// `settings` as a [`RunSpec`] (keys left out take its defaults).
///
/// # Errors
/// `TypeError` for an unknown key or a value of the wrong type; `ValueError` for a value
/// no setting can take (a negative seed, a compute time or executor that does not parse,
/// a stall of 0 s).
pub fn from_settings(settings: &Bound<'_, PyDict>) -> PyResult<RunSpec> {
    known_keys(settings, "run", &KEYS)?;
    read_spec(settings)
}

/// Exercise `which`'s run from `settings` (a dict keyed by `ratelab.exercise`'s keywords,
/// [`EXERCISE_KEYS`]; `dir` defaults to `exercises`), with `prediction` in place of the
/// learner's file's when given.
///
/// # Errors
/// As [`from_settings`], for `exercise()`.
pub fn exercise_from(
    which: String,
    settings: &Bound<'_, PyDict>,
    prediction: Option<toml::Table>,
) -> PyResult<ExerciseSpec> {
    known_keys(settings, "exercise", &EXERCISE_KEYS)?;
    let dir = get::<PathBuf>(settings, "dir", "a path")?;
    Ok(ExerciseSpec {
        which,
        dir: dir.unwrap_or_else(|| PathBuf::from("exercises")),
        graph: read_spec(settings)?.graph,
        prediction,
    })
}

/// `settings` as a [`RunSpec`], its keys already known.
fn read_spec(settings: &Bound<'_, PyDict>) -> PyResult<RunSpec> {
    let mut spec = RunSpec::default();
    let g = &mut spec.graph;
    g.file = get::<PathBuf>(settings, "graph", "a path")?;
    g.rates = get(settings, "rate", "{node: hz}")?.unwrap_or_default();
    g.depths = get(settings, "depth", "{topic: messages}")?.unwrap_or_default();
    g.qos = get(settings, "qos", "{topic: 'key=value,…'}")?.unwrap_or_default();
    g.links = get(settings, "link", "{topic: 'key=value,…'}")?.unwrap_or_default();
    g.leases_ms = get(settings, "lease_ms", "{node: ms}")?.unwrap_or_default();
    let stalls: Vec<(String, f64, f64)> =
        get(settings, "stall", "{node: (at_s, for_s)}")?.unwrap_or_default();
    for (node, at_s, for_s) in stalls {
        let duration = fault_time("stall", &node, for_s)?;
        if duration == Nanos::ZERO {
            return Err(PyValueError::new_err(format!(
                "stall[{node:?}]: a stall of 0 s does nothing"
            )));
        }
        let at = fault_time("stall", &node, at_s)?;
        g.stalls.push(Fault {
            node,
            at,
            duration: Some(duration),
        });
    }
    let kills: Vec<(String, f64)> = get(settings, "kill", "{node: at_s}")?.unwrap_or_default();
    for (node, at_s) in kills {
        let at = fault_time("kill", &node, at_s)?;
        g.kills.push(Fault {
            node,
            at,
            duration: None,
        });
    }
    let computes: Vec<(String, String)> =
        get(settings, "compute_ms", "{node: ms}")?.unwrap_or_default();
    for (node, ms) in computes {
        let c = ComputeTime::parse(&ms)
            .map_err(|e| PyValueError::new_err(format!("compute_ms[{node:?}]={ms}: {e}")))?;
        g.computes.push((node, c));
    }
    if let Some(kind) = get::<String>(settings, "executor", "a str")? {
        g.executor = Some(
            ExecutorOverride::parse(&kind)
                .map_err(|e| PyValueError::new_err(format!("executor={kind:?}: {e}")))?,
        );
    }
    read_run(settings, &mut spec)?;
    Ok(spec)
}

/// The run's own settings (not the graph's) from `settings` into `spec`.
fn read_run(settings: &Bound<'_, PyDict>, spec: &mut RunSpec) -> PyResult<()> {
    if let Some(clock) = get::<String>(settings, "clock", "'real' or 'virtual'")? {
        spec.clock = clock.parse().map_err(|_| {
            PyValueError::new_err(format!("clock must be 'real' or 'virtual', got {clock:?}"))
        })?;
    }
    if let Some(seed) = get::<i128>(settings, "seed", "an int")? {
        spec.seed = u64::try_from(seed).map_err(|_| {
            PyValueError::new_err(format!(
                "seed must be a whole number in 0..={}, got {seed}",
                u64::MAX
            ))
        })?;
    }
    spec.duration_s = get(settings, "duration_s", "a number of seconds")?;
    spec.control_hz = get(settings, "control_hz", "a rate in Hz")?;
    spec.sensor_hz = get(settings, "sensor_hz", "a rate in Hz")?;
    if let Some(depth) = get::<i128>(settings, "queue_depth", "an int")? {
        spec.queue_depth = Some(usize::try_from(depth).map_err(|_| {
            let rule = match depth < 1 {
                true => "must be at least 1".to_string(),
                false => format!("must be in 1..={}", ratelab::qos::MAX_DEPTH),
            };
            PyValueError::new_err(format!("queue_depth {rule}, got {depth}"))
        })?);
    }
    spec.phase_offset_ms = get(settings, "phase_offset_ms", "a list of ms")?.unwrap_or_default();
    if let Some(policy) = get::<String>(settings, "policy", "a str")? {
        spec.policy = policy;
    }
    let o = &mut spec.outputs;
    o.record = get::<PathBuf>(settings, "record", "a path")?.map(Some);
    o.out = get(settings, "out", "a path")?;
    o.force = get(settings, "force", "a bool")?.unwrap_or(false);
    if let Some(every) = get::<i128>(settings, "trace_every", "an int")? {
        o.trace_every = u64::try_from(every)
            .ok()
            .filter(|n| *n >= 1)
            .ok_or_else(|| {
                let rule = match every < 1 {
                    true => "must be at least 1".to_string(),
                    false => format!("must be in 1..={}", u64::MAX),
                };
                PyValueError::new_err(format!("trace_every {rule}, got {every}"))
            })?;
    }
    Ok(())
}

/// The whole numbers of `key` in `settings` as `T` (seeds, depths); `None` when left out.
///
/// # Errors
/// `TypeError` for a value that is not a list of ints; `ValueError` for one `T` cannot hold
/// (negative), naming the key and the value.
fn wholes<T: TryFrom<i128>>(
    settings: &Bound<'_, PyDict>,
    key: &str,
    what: &str,
) -> PyResult<Option<Vec<T>>> {
    let Some(values) = get::<Vec<i128>>(settings, key, "a list of ints")? else {
        return Ok(None);
    };
    values
        .into_iter()
        .map(|v| {
            T::try_from(v)
                .map_err(|_| PyValueError::new_err(format!("{key} must be {what}, got {v}")))
        })
        .collect::<PyResult<Vec<T>>>()
        .map(Some)
}

/// The `seeds` of `settings` (each in 0..=u64::MAX); `None` when left out.
fn seeds(settings: &Bound<'_, PyDict>) -> PyResult<Option<Vec<u64>>> {
    wholes(
        settings,
        "seeds",
        &format!("whole numbers in 0..={}", u64::MAX),
    )
}

/// `ratelab.sweep`'s settings as a [`SweepSpec`]: `settings` what every run shares (the keys
/// of [`SHARED_KEYS`]), `grid` the grid's lists (keys left out take `ratelab sweep`'s
/// defaults, [`SweepSpec::default`]).
///
/// # Errors
/// As [`from_settings`]; an unknown key of either dict, a clock that is neither `real` nor
/// `virtual`, a negative seed or depth.
pub fn sweep_from(settings: &Bound<'_, PyDict>, grid: &Bound<'_, PyDict>) -> PyResult<SweepSpec> {
    known_keys(settings, "sweep", &SHARED_KEYS)?;
    known_keys(grid, "sweep", &GRID_KEYS)?;
    let mut spec = SweepSpec {
        base: read_spec(settings)?,
        ..SweepSpec::default()
    };
    if let Some(clocks) = get::<Vec<String>>(grid, "clock", "a list of 'real' or 'virtual'")? {
        spec.clocks = clocks
            .iter()
            .map(|c| {
                c.parse::<ClockKind>().map_err(|_| {
                    PyValueError::new_err(format!("clock must be 'real' or 'virtual', got {c:?}"))
                })
            })
            .collect::<PyResult<_>>()?;
    }
    if let Some(hz) = get(grid, "sensor_hz", "a list of rates in Hz")? {
        spec.sensor_hz = hz;
    }
    if let Some(hz) = get(grid, "control_hz", "a list of rates in Hz")? {
        spec.control_hz = hz;
    }
    if let Some(depths) = wholes(grid, "queue_depth", "at least 1")? {
        spec.queue_depth = depths;
    }
    if let Some(seeds) = seeds(grid)? {
        spec.seeds = seeds;
    }
    Ok(spec)
}

/// `ratelab.cliff`'s settings as a [`CliffSpec`]: `settings` what every run shares (the keys
/// of [`SHARED_KEYS`], `sensor_hz` and `queue_depth`), `search` the seeds and the range
/// (keys left out take `ratelab cliff`'s defaults, [`CliffSpec::default`]).
///
/// # Errors
/// As [`from_settings`]; an unknown key of either dict, a negative seed.
pub fn cliff_from(settings: &Bound<'_, PyDict>, search: &Bound<'_, PyDict>) -> PyResult<CliffSpec> {
    known_keys(settings, "cliff", &CLIFF_KEYS)?;
    known_keys(search, "cliff", &SEARCH_KEYS)?;
    let mut spec = CliffSpec::default();
    let defaults = spec.base.clone();
    spec.base = read_spec(settings)?;
    // Left out, the command line's: sensor 50 Hz, depth 1.
    spec.base.sensor_hz = spec.base.sensor_hz.or(defaults.sensor_hz);
    spec.base.queue_depth = spec.base.queue_depth.or(defaults.queue_depth);
    spec.base.clock = defaults.clock;
    if let Some(seeds) = seeds(search)? {
        spec.seeds = seeds;
    }
    for (key, field) in [
        ("min_hz", &mut spec.min_hz),
        ("max_hz", &mut spec.max_hz),
        ("step_hz", &mut spec.step_hz),
    ] {
        if let Some(hz) = get(search, key, "a rate in Hz")? {
            *field = hz;
        }
    }
    Ok(spec)
}
