//! `ratelab.run`'s settings (a dict keyed by its keywords, made by the package's Python
//! side) as the library's [`RunSpec`]: Python's half of a run's set-up. Every rule of the
//! values is [`RunSpec::config`]'s; here only their types are read, and a wrong type is a
//! `TypeError` naming the keyword.
//!
//! The keys, each optional (left out: `ratelab run`'s default):
//! `graph` (str), `clock` ("real" | "virtual"), `seed` (int ≥ 0), `duration_s`,
//! `control_hz`, `sensor_hz` (float), `queue_depth` (int), `rate` ([(node, hz)]),
//! `depth` ([(topic, n)]), `qos`, `link` ([(topic, "key=value,…")]), `lease_ms`
//! ([(node, ms)]), `stall` ([(node, at_s, for_s)]), `kill` ([(node, at_s)]), `compute_ms`
//! ([(node, "30" | "30±5")]), `executor` (str), `phase_offset_ms` ([float]), `policy`
//! (str), `record`, `out` (str), `force` (bool), `trace_every` (int ≥ 1).

use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use ratelab::executor::{ComputeTime, ExecutorOverride};
use ratelab::qos::Fault;
use ratelab::run_spec::RunSpec;
use ratelab::time::{Nanos, MAX_DURATION_S};
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
        Some(v) => v.extract::<T>().map(Some).map_err(|_| {
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
    for key in settings.keys() {
        let key: String = key.extract()?;
        if !KEYS.contains(&key.as_str()) {
            return Err(PyTypeError::new_err(format!(
                "run() got an unexpected setting '{key}' (settings: {})",
                KEYS.join(", ")
            )));
        }
    }
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
            PyValueError::new_err(format!("queue_depth must be at least 1, got {depth}"))
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
                PyValueError::new_err(format!("trace_every must be at least 1, got {every}"))
            })?;
    }
    Ok(())
}
