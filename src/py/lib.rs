//! ratelab's Python API inside the caller's interpreter: what the wheel's extension module
//! `ratelab._native` holds for the package in `python/ratelab/` (which is what a user
//! imports), over the library alone (no terminal or command-line crate: the wheel's own
//! crate, `src/wheel`, adds the `ratelab` command beside it).
//!
//! - `run`: one run from `ratelab.run`'s settings (`run_spec`: a dict of its keywords,
//!   read into the library's `RunSpec`, no argument list) and started as `ratelab run` starts
//!   one (`RunSpec::start`, through `ratelab::held_run`), its files' contents returned;
//!   Python nodes and a callable brain run in this interpreter. Ctrl-C (KeyboardInterrupt)
//!   stops it.
//! - `sweep`, `cliff`: a sweep and a cliff search from `ratelab.sweep`'s and
//!   `ratelab.cliff`'s settings (`run_spec`: dicts read into the library's `SweepSpec` and
//!   `CliffSpec`), their tables as CSV (`ratelab sweep --csv`'s); a callable brain runs in
//!   this interpreter, a fresh wrapper of it per run, the runs on every core.
//! - `exercise`: `ratelab exercise`, its checks returned (a prediction may be given).
//!
//! [`register`] adds them to a module and makes the interpreter ratelab's host ([`hosted`]).
//! Errors become Python exceptions carrying the library's one line: a missing file
//! `FileNotFoundError`, one refused for being there `FileExistsError`, a permission
//! `PermissionError`, a run whose trace would not fit in memory `TraceTooLarge` (a
//! `MemoryError`, raised before the run), anything else the caller gave wrong `ValueError`.
//! Nothing here ends the process.
#![warn(missing_docs)]

use pyo3::exceptions::{
    PyFileExistsError, PyFileNotFoundError, PyIsADirectoryError, PyKeyboardInterrupt,
    PyMemoryError, PyNotADirectoryError, PyOSError, PyPermissionError, PyRuntimeError,
    PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use ratelab::distributed::launcher::Program;
use ratelab::policy::Policy;
use ratelab::python::brain::PythonBrain;
use ratelab::scheduler::StopFlag;
use ratelab::setting::Speech;

mod run_spec;
use std::time::Duration;

pyo3::create_exception!(
    _native,
    NoPrediction,
    PyValueError,
    "An exercise was asked for before its prediction was written (`ratelab exercise` refuses it)."
);

pyo3::create_exception!(
    _native,
    RunInProgress,
    PyRuntimeError,
    "A run, sweep, cliff search or exercise started from inside a run's brain or node, or from a thread that such a callback is joining: the run in progress holds the process's one run until that callback returns."
);

pyo3::create_exception!(
    _native,
    TraceTooLarge,
    PyMemoryError,
    "A run whose trace, returned in memory, would hold more values than ratelab's bound (ratelab::limits::MAX_HELD_TRACE_VALUES): refused before it starts."
);

/// How often a run waiting in [`run`] looks for Ctrl-C.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// ratelab in a host interpreter, once, when the module is imported: its Python is this
/// one, a launch starts its processes as `sys.executable -m ratelab`, and the Python and ROS
/// 2 layers are installed (`ratelab::init`).
///
/// # Errors
/// `sys.executable` cannot be read.
pub fn hosted(py: Python<'_>) -> PyResult<()> {
    ratelab::python::host();
    ratelab::init();
    let exe: String = py.import("sys")?.getattr("executable")?.extract()?;
    Program::set_this(Program {
        path: exe.into(),
        args: vec!["-m".into(), "ratelab".into()],
    });
    Ok(())
}

/// The error `e` as the Python exception its cause calls for, with the library's one line.
fn to_py(e: &anyhow::Error) -> PyErr {
    let text = match e.downcast_ref::<ratelab::graph::spec::SpecError>() {
        Some(spec) => spec.to_string(),
        None => ratelab::text::printable(&format!("{e:#}")).to_string(),
    };
    for cause in e.chain() {
        if let Some(ratelab_exercises::ExerciseError::NoPrediction { .. }) = cause.downcast_ref() {
            return NoPrediction::new_err(text);
        }
        if cause
            .downcast_ref::<ratelab::held_run::TraceTooLarge>()
            .is_some()
        {
            return TraceTooLarge::new_err(text);
        }
        let missing = match cause.downcast_ref::<ratelab::graph::spec::SpecError>() {
            Some(spec) => spec.is_missing_file(),
            None => matches!(
                cause.downcast_ref::<ratelab::checkpoint::PolicyError>(),
                Some(ratelab::checkpoint::PolicyError::NotFound(_))
            ),
        };
        if missing {
            return PyFileNotFoundError::new_err(text);
        }
        if let Some(i) = cause.downcast_ref::<ratelab::input::InputError>() {
            use ratelab::input::InputError;
            match i {
                InputError::NotFound(_) => return os_error(std::io::ErrorKind::NotFound, text),
                InputError::PermissionDenied(_) => {
                    return os_error(std::io::ErrorKind::PermissionDenied, text)
                }
                _ => {}
            }
        }
        if let Some(r) = cause.downcast_ref::<ratelab::outputs::RecordRefused>() {
            use ratelab::recording::RecordingError;
            return match r.cause {
                RecordingError::Exists(_) => PyFileExistsError::new_err(text),
                RecordingError::IsDirectory(_) => PyIsADirectoryError::new_err(text),
                // A folder that is not there or not the user's: Python's own subclass; a disk
                // that filled, rerun failing to write: the system's, not a setting.
                RecordingError::Unwritable { kind, .. } => os_error(kind, text),
                RecordingError::Rerun { .. } => PyOSError::new_err(text),
                // Its file moved or removed under it while the run went: the system's too.
                RecordingError::Output(ratelab::output::OutputError::Replaced(_)) => {
                    PyOSError::new_err(text)
                }
                _ => PyValueError::new_err(text),
            };
        }
        if let Some(o) = cause.downcast_ref::<ratelab::output::OutputError>() {
            if let ratelab::output::OutputError::Exists(path) = o {
                // In Python's words: the keyword, not the flag.
                let said = format!(
                    "{}: file exists (pass {} to overwrite)",
                    path.display(),
                    Speech::Keywords.force()
                );
                return PyFileExistsError::new_err(text.replace(&o.to_string(), &said));
            }
            // The file system refused (`out="/proc"`, a full or read-only disk), as a
            // recording's refusal is said: not a setting.
            if let ratelab::output::OutputError::Io { kind, .. } = o {
                return os_error(*kind, text);
            }
        }
        if let Some(io) = cause.downcast_ref::<std::io::Error>() {
            return os_error(io.kind(), text);
        }
        // A policy path that names a folder, or a file it may not read: Python's own kinds.
        if let Some(p) = cause.downcast_ref::<ratelab::checkpoint::PolicyError>() {
            use ratelab::checkpoint::PolicyError;
            use ratelab::input::InputError;
            match p {
                PolicyError::NotAFile(path) if path.is_dir() => {
                    return PyIsADirectoryError::new_err(text)
                }
                PolicyError::Unreadable(InputError::PermissionDenied(_)) => {
                    return os_error(std::io::ErrorKind::PermissionDenied, text)
                }
                _ => {}
            }
        }
    }
    PyValueError::new_err(text)
}

/// The OS error of `kind` as Python's subclass of `OSError` for it (`PermissionError`,
/// `FileNotFoundError`, …), with the library's one line; a kind without one (a full disk, a
/// read-only one) a plain `OSError`: the file system refused, not a setting.
fn os_error(kind: std::io::ErrorKind, text: String) -> PyErr {
    use std::io::ErrorKind;
    match kind {
        ErrorKind::NotFound => PyFileNotFoundError::new_err(text),
        ErrorKind::PermissionDenied => PyPermissionError::new_err(text),
        ErrorKind::IsADirectory => PyIsADirectoryError::new_err(text),
        ErrorKind::NotADirectory => PyNotADirectoryError::new_err(text),
        ErrorKind::AlreadyExists => PyFileExistsError::new_err(text),
        _ => PyOSError::new_err(text),
    }
}

/// One run, sweep, cliff search or exercise of this process at a time: a second call from
/// another thread waits for the first (the interpreter let go meanwhile, Ctrl-C heard),
/// unless a callback of the run in progress is joining this thread
/// ([`ratelab::python::callback_joining_this_thread`]: it started the thread, then waits
/// for it), and the call is refused rather than left to wait for ever. A
/// run's text log, its failed node's exception and the node classes given to it are the
/// process's while it goes (`ratelab_core::textlog`'s sink, `ratelab::python`'s failure and
/// classes), so two at once would mix their logs.
///
/// # Errors
/// KeyboardInterrupt while waiting; `RunInProgress` (a RuntimeError) at once when called
/// from inside a run's node or brain (`call`, e.g. `ratelab.run`, is what it says was called): the outer run
/// holds the lock until that callback returns, so waiting would never end; and while
/// waiting, when a callback of the run in progress joins this thread (above).
fn one_at_a_time(py: Python<'_>, call: &str) -> PyResult<std::sync::MutexGuard<'static, ()>> {
    if let Some((what, loading)) = ratelab::python::callback_of_this_thread() {
        // The likeliest way here: a node's or brain's script with a run at its top level,
        // which runs again when ratelab loads the script.
        let hint = match loading {
            true => " (a script's top-level code runs again when ratelab loads it: put the run under `if __name__ == \"__main__\":`)",
            false => "",
        };
        return Err(RunInProgress::new_err(format!(
            "{call}() was called from inside a run ({what}): a run cannot start another \
             in the same process; start it after the run in progress returns{hint}"
        )));
    }
    static ONE: std::sync::Mutex<()> = std::sync::Mutex::new(());
    loop {
        match ONE.try_lock() {
            Ok(guard) => return Ok(guard),
            // A run that panicked left nothing of its own behind the lock.
            Err(std::sync::TryLockError::Poisoned(p)) => return Ok(p.into_inner()),
            Err(std::sync::TryLockError::WouldBlock) => {
                if let Some(what) = ratelab::python::callback_joining_this_thread(py)? {
                    return Err(RunInProgress::new_err(format!(
                        "{call}() was called from a thread that {what} of the run in \
                         progress is joining: that run holds the process's one run until \
                         its callback returns, so neither could go on; start this run after \
                         the run in progress returns"
                    )));
                }
                py.detach(|| std::thread::sleep(SIGNAL_POLL / 5));
                py.check_signals()?;
            }
        }
    }
}

/// Do `work` on a thread of its own, its Python output going to the run's text log, while
/// this (the main) thread waits without the GIL (Python nodes need it) and looks for Ctrl-C:
/// only the main thread sees Python's signals. A Ctrl-C stops the work (its stop flag, and
/// a Python callback that does not return) and raises KeyboardInterrupt.
///
/// # Errors
/// KeyboardInterrupt; the work's own error as [`to_py`] maps it.
fn interruptibly<T: Send + 'static>(
    py: Python<'_>,
    work: impl FnOnce(StopFlag) -> anyhow::Result<T> + Send + 'static,
) -> PyResult<T> {
    let capture = ratelab::python::capture_output().ok();
    let stop = StopFlag::new();
    let (tx, rx) = crossbeam_channel::bounded(1);
    let running = {
        let stop = stop.clone();
        std::thread::Builder::new()
            .name("ratelab-run".into())
            .spawn(move || {
                let _ = tx.send(work(stop));
            })
            .map_err(|e| PyValueError::new_err(format!("cannot start the run: {e}")))?
    };
    let mut interrupted = None;
    let result = loop {
        match py.detach(|| rx.recv_timeout(SIGNAL_POLL)) {
            Ok(r) => break r,
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => {
                break Err(anyhow::anyhow!("the run ended without a result"))
            }
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
        }
        if interrupted.is_none() {
            if let Err(e) = py.check_signals() {
                stop.stop();
                // A Python callback that never returns would hold the run: interrupt it.
                ratelab::python::interrupt_callbacks_after(ratelab::python::PYTHON_GRACE);
                interrupted = Some(e);
            }
        }
    };
    py.detach(|| {
        let _ = running.join();
    });
    drop(capture);
    if let Some(e) = interrupted {
        return Err(if e.is_instance_of::<PyKeyboardInterrupt>(py) {
            e
        } else {
            PyKeyboardInterrupt::new_err("the run was interrupted")
        });
    }
    result.map_err(|e| to_py(&e))
}

/// A factory of brains calling `callable` (a Python function `f(obs) -> action`), checked
/// once here (callable, NumPy importable): each run gets a fresh wrapper of it
/// ([`PythonBrain::from_callable`]). A wrapper takes the GIL for each call (`Python::attach`),
/// so runs on several threads call it in turn; the one function object is every run's, so
/// state it keeps between calls is shared by the runs.
///
/// # Errors
/// `ValueError` when it is not callable or NumPy cannot be imported.
fn callable_brains(py: Python<'_>, callable: Py<PyAny>) -> PyResult<Brains> {
    PythonBrain::from_callable(callable.clone_ref(py))
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(Box::new(move || {
        let f = Python::attach(|py| callable.clone_ref(py));
        PythonBrain::from_callable(f)
            .map(|b| Box::new(b) as Box<dyn Policy>)
            .map_err(|e| e.to_string())
    }))
}

/// A factory of fresh brains, for the runs of a sweep or search (on several threads).
type Brains = Box<dyn Fn() -> Result<Box<dyn Policy>, String> + Send + Sync>;

/// `work` with the brains of `callable` when given, else of `policy` (a name, file or
/// checkpoint: loaded once to check it, then for each run).
///
/// # Errors
/// The brain cannot be loaded; `work`'s own.
fn with_brains<T>(
    callable: Option<&Brains>,
    policy: &str,
    work: impl FnOnce(ratelab::sweep::BrainFactory<'_>) -> anyhow::Result<T>,
) -> anyhow::Result<T> {
    match callable {
        Some(brains) => work(&**brains),
        None => work(&ratelab::sweep_spec::brain_factory(policy)?),
    }
}

/// A sweep in this process, of `settings` (a dict of what every run shares, keyed by
/// `ratelab.sweep`'s keywords) and `grid` (its lists: `clock`, `sensor_hz`, `control_hz`,
/// `queue_depth`, `seeds`; see [`run_spec`]), with `brain` (a callable `f(obs) -> action`)
/// as every run's brain when given: `(csv, failed)`, its table as `ratelab sweep --csv`
/// writes it and the line of the first run that failed a node (or None). Runs go on every
/// core; a callable brain is called under the GIL, one call at a time. Refusals name the
/// keywords (`seeds: an empty list runs nothing …`). Ctrl-C stops it.
#[pyfunction]
#[pyo3(signature = (settings, grid, brain=None))]
fn sweep<'py>(
    py: Python<'py>,
    settings: &Bound<'py, PyDict>,
    grid: &Bound<'py, PyDict>,
    brain: Option<Py<PyAny>>,
) -> PyResult<(String, Option<String>)> {
    let _one = one_at_a_time(py, "ratelab.sweep")?;
    let spec = run_spec::sweep_from(settings, grid)?;
    let brains = brain.map(|f| callable_brains(py, f)).transpose()?;
    let done = interruptibly(py, move |stop| {
        let rows = with_brains(brains.as_ref(), &spec.base.policy, |brain| {
            spec.run(Speech::Keywords, brain, &|_, _| {}, &stop)
        })?;
        let mut csv = Vec::new();
        ratelab::sweep::write_csv(&mut csv, &rows)?;
        Ok((String::from_utf8(csv)?, ratelab::sweep::failed_line(&rows)))
    });
    // A failed run's Python exception is not kept for a later run.
    drop(ratelab::python::take_failure());
    done
}

/// A cliff search in this process, of `settings` (a dict of what every run shares, keyed by
/// `ratelab.cliff`'s keywords) and `search` (`seeds`, `min_hz`, `max_hz`, `step_hz`; see
/// [`run_spec`]), with `brain` (a callable `f(obs) -> action`) as every run's brain when
/// given: per seed the highest control rate at which the pole falls, as CSV
/// (`seed,falls_at_hz,balances_at_hz,runs`). Seeds go on every core; a callable brain is
/// called under the GIL, one call at a time. Refusals name the keywords. Ctrl-C stops it.
#[pyfunction]
#[pyo3(signature = (settings, search, brain=None))]
fn cliff<'py>(
    py: Python<'py>,
    settings: &Bound<'py, PyDict>,
    search: &Bound<'py, PyDict>,
    brain: Option<Py<PyAny>>,
) -> PyResult<String> {
    let _one = one_at_a_time(py, "ratelab.cliff")?;
    let spec = run_spec::cliff_from(settings, search)?;
    let brains = brain.map(|f| callable_brains(py, f)).transpose()?;
    let done = interruptibly(py, move |stop| {
        let cliffs = with_brains(brains.as_ref(), &spec.base.policy, |brain| {
            spec.run(Speech::Keywords, brain, &|_, _| {}, &stop)
        })?;
        let mut csv = Vec::new();
        ratelab::sweep::write_cliffs_csv(&mut csv, &cliffs)?;
        Ok(String::from_utf8(csv)?)
    });
    drop(ratelab::python::take_failure());
    done
}

/// Exercise `which` in this process, as `ratelab exercise` runs it, with `settings` (a dict
/// keyed by `ratelab.exercise`'s keywords: `dir`, `graph` and the graph's overrides) and
/// `prediction_json` (a JSON object) in place of the learner's file's prediction when
/// given. Returns a dict: `checks` (a list of `(name, passed)`), `reconcile` (sentences),
/// `predictions` (a list of `(key, sentence, verdict)`, the verdict `right`, `missed`,
/// `unreadable` or `open`), `checks_failed`, `predictions_missed` and `not_passed` (counts:
/// missed counts the unreadable too, and not passed is both) and `lines` (the report
/// `ratelab exercise` prints). Ctrl-C ends the run in progress and raises
/// KeyboardInterrupt, nothing graded.
#[pyfunction]
#[pyo3(signature = (which, settings, prediction_json=None))]
fn exercise<'py>(
    py: Python<'py>,
    which: String,
    settings: &Bound<'py, PyDict>,
    prediction_json: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let _one = one_at_a_time(py, "ratelab.exercise")?;
    let prediction: Option<toml::Table> = prediction_json
        .map(|json| serde_json::from_str(&json))
        .transpose()
        .map_err(|e| PyValueError::new_err(format!("prediction: {e}")))?;
    let spec = run_spec::exercise_from(which, settings, prediction)?;
    let (report, lines) = interruptibly(py, move |stop| {
        let mut lines = Vec::new();
        let mut out = |text: &str| lines.extend(text.lines().map(str::to_string));
        let report = spec.report(Speech::Keywords, &mut out, &(), &stop)?;
        Ok((report, lines))
    })?;
    let out = PyDict::new(py);
    let checks: Vec<(String, bool)> = (report.checks.iter())
        .map(|c| (c.name.clone(), c.passed))
        .collect();
    out.set_item("checks", checks)?;
    let reconcile: Vec<String> = (report.reconcile.iter()).map(|s| s.line.clone()).collect();
    out.set_item("reconcile", reconcile)?;
    let predictions: Vec<(String, String, &str)> = (report.reconcile.iter())
        .map(|s| (s.key.clone(), s.line.clone(), s.verdict.name()))
        .collect();
    out.set_item("predictions", predictions)?;
    out.set_item("checks_failed", report.checks_failed)?;
    out.set_item("predictions_missed", report.predictions_missed)?;
    out.set_item("not_passed", report.not_passed)?;
    out.set_item("lines", lines)?;
    Ok(out)
}

/// Put ratelab's message classes (`State`, `Position`, `Force`, the types a program
/// registered) and `Time` into the `ratelab` package, as Python nodes see them.
#[pyfunction]
fn install_messages(py: Python<'_>) -> PyResult<()> {
    ratelab::python::start().map_err(|e| PyValueError::new_err(e.to_string()))?;
    ratelab::python::install_messages(py)
}

/// The exercises, in order: `(id, file, title)` each (`("ex1", "ex1_rate_cliff.toml", "the
/// rate cliff")`).
#[pyfunction]
fn exercises() -> Vec<(&'static str, &'static str, &'static str)> {
    (ratelab_exercises::EXERCISES.iter())
        .map(|e| (e.id(), e.file(), e.title()))
        .collect()
}

/// One run in this process, of `settings` (a dict keyed by `ratelab.run`'s keywords: see
/// [`run_spec`]), with `policy` (a callable taking the observation, a NumPy float32[5]
/// array, and returning the force command) as its brain when given, and `nodes` (`(node
/// name, class)` pairs) making those Python nodes of the graph from classes of this
/// interpreter. Returns a dict: `metrics_json`, `trace_csv`, `log` (the files' texts),
/// `estimator_json` (`estimator.json`'s text with an estimator in the graph, else None),
/// `trace_columns` (the trace as `(name, dtype, bytes)` per column), `summary` (lines),
/// `failed` (the line of a node that failed, or None), `failed_exception` (the Python
/// exception that failed it, with its traceback, when it was Python code's), `recording`
/// (its path or None). Refusals name the keywords (`control_hz must be …`). Ctrl-C stops the run and raises
/// KeyboardInterrupt; a trace that would pass `MAX_HELD_TRACE_VALUES` raises
/// `TraceTooLarge` (a MemoryError) before the run.
#[pyfunction]
#[pyo3(signature = (settings, policy=None, nodes=Vec::new()))]
fn run<'py>(
    py: Python<'py>,
    settings: &Bound<'py, PyDict>,
    policy: Option<Py<PyAny>>,
    nodes: Vec<(String, Py<PyAny>)>,
) -> PyResult<Bound<'py, PyDict>> {
    let _one = one_at_a_time(py, "ratelab.run")?;
    let spec = run_spec::from_settings(settings)?;
    let classes: Vec<String> = nodes.iter().map(|(n, _)| n.clone()).collect();
    let _given = ratelab::python::node::give_classes(nodes);
    let brain = match policy {
        Some(f) => Some(Box::new(
            PythonBrain::from_callable(f).map_err(|e| PyValueError::new_err(e.to_string()))?,
        ) as Box<dyn Policy>),
        None => None,
    };
    // An earlier run's failure is not this one's.
    drop(ratelab::python::take_failure());
    // Faults set after the run ends, which do nothing: Python warns of them (RuntimeWarning).
    // Settings that cannot be used are the run's to refuse, below.
    let late = (spec.config(Speech::Keywords).ok())
        .map(|cfg| ratelab::run_spec::late_fault_warnings(&cfg, Speech::Keywords))
        .unwrap_or_default();
    let files = interruptibly(py, move |stop| {
        ratelab::held_run::run(&spec, brain, &classes, Speech::Keywords, stop)
    })
    .inspect_err(|e| {
        // Refused for a Python exception (a brain file's import failing, a node class's
        // `__init__` raising): that exception, with its traceback, is the cause, as a
        // failed node's is `NodeFailed`'s. Only when the refusal says it: a node's exception
        // is never the cause of an error that came after it (a recording left unwritten).
        let said = e.value(py).str().map(|s| s.to_string()).unwrap_or_default();
        if let Some((cause, _)) = ratelab::python::take_failure_said()
            .filter(|(_, line)| !line.is_empty() && said.contains(line.as_str()))
        {
            e.set_cause(py, Some(cause));
        }
    })?;
    let out = PyDict::new(py);
    out.set_item("warnings", late)?;
    out.set_item("metrics_json", files.metrics_json)?;
    out.set_item("estimator_json", files.estimator_json)?;
    // A long run's trace is the largest thing here: its text goes to Python first and the
    // columns are made from Python's copy, so the text is never held twice beside them.
    let trace_csv = pyo3::types::PyString::new(py, &files.trace_csv);
    drop(files.trace_csv);
    let columns = trace_columns(trace_csv.to_str()?).map_err(|e| to_py(&e))?;
    let columns: Vec<_> = columns
        .into_iter()
        .map(|(n, k, b)| (n, k, pyo3::types::PyBytes::new(py, &b)))
        .collect();
    out.set_item("trace_columns", columns)?;
    out.set_item("trace_csv", trace_csv)?;
    out.set_item("log", files.log)?;
    out.set_item("summary", files.summary)?;
    // The node's own exception, with its traceback: `NodeFailed`'s `__cause__`.
    let cause = files
        .failed
        .as_ref()
        .and_then(|_| ratelab::python::take_failure())
        .map(|e| e.into_value(py));
    out.set_item("failed_exception", cause)?;
    out.set_item("failed", files.failed)?;
    out.set_item("wall_s", files.wall_s)?;
    out.set_item(
        "recording",
        files.recording.map(|p| p.to_string_lossy().into_owned()),
    )?;
    Ok(out)
}

/// `trace.csv`'s text as columns, each `(name, dtype, bytes)` for `numpy.frombuffer`: the
/// time series as `float64` (`pole_angle`, `cart_pos`, `action`, `latency_ns`; an empty
/// cell NaN), the flags as `bool`, the counters as `int64`, little-endian, in the file's
/// column order. Parsing the text keeps one writer of the columns (the command line's).
fn trace_columns(csv_text: &str) -> anyhow::Result<Vec<(String, &'static str, Vec<u8>)>> {
    const FLOATS: [&str; 4] = ["pole_angle", "cart_pos", "action", "latency_ns"];
    const FLAGS: [&str; 2] = ["nonfinite", "fell"];
    let mut reader = csv::Reader::from_reader(csv_text.as_bytes());
    let names: Vec<String> = reader.headers()?.iter().map(str::to_string).collect();
    let kinds: Vec<&'static str> = names
        .iter()
        .map(|n| {
            if FLOATS.contains(&n.as_str()) {
                "<f8"
            } else if FLAGS.contains(&n.as_str()) {
                "?"
            } else {
                "<i8"
            }
        })
        .collect();
    let mut columns: Vec<Vec<u8>> = vec![Vec::new(); names.len()];
    for row in reader.records() {
        let row = row?;
        for ((cell, kind), column) in row.iter().zip(&kinds).zip(&mut columns) {
            match *kind {
                "<f8" => {
                    let x = if cell.is_empty() {
                        f64::NAN
                    } else {
                        cell.parse()?
                    };
                    column.extend_from_slice(&x.to_le_bytes());
                }
                "?" => column.push(u8::from(cell == "true")),
                _ => column.extend_from_slice(&cell.parse::<i64>()?.to_le_bytes()),
            }
        }
    }
    Ok(names
        .into_iter()
        .zip(kinds)
        .zip(columns)
        .map(|((n, k), c)| (n, k, c))
        .collect())
}

/// Add the Python API to `m` (the wheel's `ratelab._native`): `run`, `sweep`, `cliff`,
/// `exercise`, `exercises`, `install_messages`, `__version__` and the exceptions
/// `NoPrediction` and `TraceTooLarge`, this interpreter made ratelab's host first
/// ([`hosted`]).
///
/// # Errors
/// A function or attribute cannot be added; [`hosted`]'s.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    hosted(m.py())?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(sweep, m)?)?;
    m.add_function(wrap_pyfunction!(cliff, m)?)?;
    m.add_function(wrap_pyfunction!(exercise, m)?)?;
    m.add_function(wrap_pyfunction!(exercises, m)?)?;
    m.add_function(wrap_pyfunction!(install_messages, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("NoPrediction", m.py().get_type::<NoPrediction>())?;
    m.add("TraceTooLarge", m.py().get_type::<TraceTooLarge>())?;
    m.add("RunInProgress", m.py().get_type::<RunInProgress>())?;
    Ok(())
}
