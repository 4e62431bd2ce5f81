//! Python inside ratelab: the embedded interpreter (PyO3) that runs learners' code — a brain
//! written as a Python function ([`brain`]), a node written like an rclpy node ([`node`]) —
//! within the graph, under either clock.
//!
//! - **Which Python.** The `libpython` ratelab was built against (the `python3` on `PATH`
//!   at build time; `.cargo/config.toml` pins `PYO3_PYTHON` so the build does not change
//!   with the shell), found at run time through an rpath, with its own installation as its
//!   home: never a `python3` or virtual environment first on `PATH` at run time ([`embed`]).
//!   An active virtual environment (`VIRTUAL_ENV`, else a conda one: `CONDA_PREFIX`) has its
//!   `site-packages` added, so `import numpy` or `import torch` work as in that
//!   environment's `python`; a `.pth` file there may not re-execute or end the process.
//! - **One interpreter, one lock.** Python code of every node shares the interpreter and its
//!   global interpreter lock (GIL): under the real clock two Python callbacks never run at
//!   once, whatever threads their nodes have. Under the virtual clock nothing changes: ticks
//!   run one at a time anyway.
//! - **Errors are one line**, `FILE:LINE: ExceptionType: message`, at the innermost frame
//!   in the learner's own folder (`support.py` formats them). A callback that raises
//!   mid-run panics with that line; the scheduler catches it and the run ends as
//!   "node 'X' failed" at that instant (`ratelab::scheduler::EndReason::NodeFailed`). A
//!   program that asks ([`log_failures`]: the terminal lab) also gets each callback's
//!   failure in the run's text log, that line carrying the learner's frames and the whole
//!   traceback (`ratelab::textlog::emit_failure`).
//! - **Callbacks that never return.** Every call into learners' code is registered
//!   ([`CallbackGuard`]); a watchdog thread warns once when one has overrun by far: a
//!   node's callbacks after [`OVERRUN_PERIODS`] of its periods, a brain's (and any loading)
//!   after [`OVERRUN_WARNING`]; and [`interrupt_callbacks`] (Ctrl-C) raises `KeyboardInterrupt`
//!   inside the ones still running (`PyThreadState_SetAsyncExc`), so a `while True: pass`
//!   cannot hang the run. The lab tries saved code on threads of their own
//!   ([`enter_trial`]): their calls are not the live run's, and a newer save interrupts
//!   them ([`interrupt_trial`]); its first Ctrl-C interrupts the live run's hung calls
//!   alone ([`interrupt_hung_callbacks`]).
//!
//! This is the Python layer, a crate above the runtime: the runtime reaches it through the
//! interpreter it installs ([`install`], the runtime's `graph::interpreter` module), so changing it
//! rebuilds only this crate and those above. [`kind`] is that interpreter.
#![warn(missing_docs)]

pub mod brain;
pub mod embed;
pub mod kind;
pub mod node;

/// Install the embedded interpreter as the one Python nodes and brains run in (the
/// runtime's `ratelab_runtime::graph::interpreter::install`); idempotent. `ratelab::init()` calls it.
pub fn install() {
    ratelab_runtime::graph::interpreter::install(&kind::Embedded);
}

use pyo3::prelude::*;
use pyo3::types::PyModule;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

pub use ratelab_core::limits::MAX_SCRIPT_BYTES;

/// A Python node's tick that runs this many of the node's periods without returning is
/// reported once on stderr (an overrun by far: 2 s at 50 Hz, 0.5 s at 200 Hz).
pub const OVERRUN_PERIODS: u32 = 100;

/// A brain's call (which does not know its node's rate) or a script's loading that runs
/// this long without returning is reported once on stderr: [`OVERRUN_PERIODS`] at the
/// chapter's 50 Hz.
pub const OVERRUN_WARNING: Duration = Duration::from_secs(2);

/// How often the watchdog looks, and so the shortest overrun it reports on time.
const WATCHDOG_POLL: Duration = Duration::from_millis(50);

/// Why Python code could not be loaded. One line each, naming the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PythonError {
    /// The interpreter could not start or lacks a module ratelab needs (NumPy).
    #[error("{0}")]
    Interpreter(String),
    /// The script could not be read (missing, not a file, too large, not UTF-8): the line,
    /// and whether the file is not there (told apart as a missing checkpoint is, Python's
    /// `FileNotFoundError`).
    #[error("{line}")]
    Input {
        /// The one line.
        line: String,
        /// The file is not there.
        missing: bool,
    },
    /// The script failed to load: a syntax error, an exception at import, a broken contract
    /// (`FILE:LINE: ExceptionType: message`).
    #[error("{0}")]
    Script(String),
}

/// The file name support.py's code carries in a traceback.
const SUPPORT_FILE_NAME: &str = "<ratelab>";
/// [`SUPPORT_FILE_NAME`] for Python's C API.
const SUPPORT_FILE_NAME_C: &std::ffi::CStr = c"<ratelab>";

const SUPPORT_SOURCE: &std::ffi::CStr = {
    const BYTES: &[u8] = concat!(include_str!("support.py"), "\0").as_bytes();
    match std::ffi::CStr::from_bytes_with_nul(BYTES) {
        Ok(s) => s,
        Err(_) => panic!("support.py holds no NUL byte"),
    }
};

/// The support module (`support.py`), once the interpreter is up.
static SUPPORT: OnceLock<Result<Py<PyModule>, String>> = OnceLock::new();

/// Start the interpreter (once per process) and return ratelab's support module.
///
/// # Errors
/// [`PythonError::Interpreter`] when the support module cannot be set up.
pub fn support(py: Python<'_>) -> Result<&Bound<'_, PyModule>, PythonError> {
    match SUPPORT.get() {
        Some(Ok(m)) => Ok(m.bind(py)),
        Some(Err(e)) => Err(PythonError::Interpreter(e.clone())),
        None => unreachable!("support() is called inside attach(), after start()"),
    }
}

/// Set by [`host`]: ratelab runs inside a Python program's interpreter (the Python package).
static HOSTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Say that ratelab runs inside a Python program's own interpreter (`import ratelab`), before
/// any Python node or brain starts: its `sys.path` is the program's (no virtual environment
/// is added), and its `sys.stdout`/`sys.stderr` are the program's but while a run goes
/// ([`capture_output`]).
pub fn host() {
    HOSTED.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// While this lives, what Python code writes to `sys.stdout`/`sys.stderr` goes to the run's
/// text log ([`ratelab_core::textlog`]), as in the `ratelab` binary; dropping the last one
/// alive puts the streams back (captures at once share one, `support.py`'s
/// `_capture_output`). For a host's interpreter ([`host`]); call it with the interpreter started.
pub struct OutputCapture(Option<Py<PyAny>>);

/// Start capturing the interpreter's output ([`OutputCapture`]).
///
/// # Errors
/// [`PythonError::Interpreter`] when the interpreter or the support module cannot start.
pub fn capture_output() -> Result<OutputCapture, PythonError> {
    start()?;
    Python::attach(|py| {
        let prev = support(py)?
            .call_method0("_capture_output")
            .map_err(|e| PythonError::Interpreter(e.to_string()))?;
        Ok(OutputCapture(Some(prev.unbind())))
    })
}

impl Drop for OutputCapture {
    fn drop(&mut self) {
        if let Some(prev) = self.0.take() {
            Python::attach(|py| {
                if let Ok(s) = support(py) {
                    let _ = s.call_method1("_restore_output", (prev,));
                }
            });
        }
    }
}

/// Start the embedded interpreter if it is not running (by ratelab's rules, [`embed`]: its
/// home from the libpython linked, never from a `python3` on `PATH`), run its start-up
/// (`site` and the active environment's packages, every `.pth` guarded), and load the
/// support module. Cheap after the first call.
///
/// # Errors
/// [`PythonError::Interpreter`] when the interpreter cannot start (one line naming the
/// interpreter found and why) or the support module cannot be loaded.
pub fn start() -> Result<(), PythonError> {
    // In a host's interpreter the caller may hold it (`ratelab.run` from two threads at once),
    // and loading the support module runs Python code, which hands the interpreter to other
    // threads between its steps: a caller holding it while waiting here would keep it from
    // the thread loading (a deadlock, observed). PyO3's `get_or_init_py_attached` lets go of
    // the interpreter while it waits. The binary's own interpreter is started here first, by
    // a thread holding nothing.
    let result = if HOSTED.load(std::sync::atomic::Ordering::Relaxed) && SUPPORT.get().is_none() {
        use pyo3::sync::OnceLockExt;
        Python::attach(|py| SUPPORT.get_or_init_py_attached(py, load_support))
    } else {
        SUPPORT.get_or_init(load_support)
    };
    start_watchdog();
    match result {
        Ok(_) => Ok(()),
        Err(e) => Err(PythonError::Interpreter(e.clone())),
    }
}

/// [`start`]'s work, once: the interpreter started if it is not running (its start-up run
/// when ratelab started it), then the support module loaded.
fn load_support() -> Result<Py<PyModule>, String> {
    let started_here = embed::initialize()?;
    // The interpreter runs now: PyO3's own initialisation only records that it is up.
    Python::initialize();
    let hosted = HOSTED.load(std::sync::atomic::Ordering::Relaxed);
    Python::attach(|py| {
        if !hosted {
            embed::run_startup(py, started_here)?;
        }
        PyModule::from_code(py, SUPPORT_SOURCE, SUPPORT_FILE_NAME_C, c"_ratelab_support")
            .and_then(|m| {
                // What learners' code writes goes to the run's text log (in a host's
                // interpreter only while a run goes: [`capture_output`]).
                m.add_function(wrap_pyfunction!(log_line, &m)?)?;
                if !hosted {
                    m.call_method0("_capture_output")?;
                }
                Ok(m)
            })
            .map(Bound::unbind)
            .map_err(|e| format!("ratelab's Python support failed to load: {e}"))
    })
}

/// `_ratelab_support._log(level, text, node=None, caller=None)`: a line (or lines) a
/// learner's code wrote (`print`, `sys.stderr`, a warning), to the run's text log
/// ([`ratelab_core::textlog`]), stamped with the calling thread's tick, or with `node` (a logger's
/// own) when given. With `caller`, `(file, function, line)` of the frame that called a
/// node's logger (`get_logger().info(text)`), `text` is that logger's message, one line:
/// shown with its level word, and on `/rosout` alone with its caller
/// ([`ratelab_core::textlog::emit_logged`]).
#[pyfunction]
#[pyo3(name = "_log", signature = (level, text, node=None, caller=None))]
fn log_line(level: &str, text: &str, node: Option<&str>, caller: Option<(String, String, u32)>) {
    use ratelab_core::textlog::{emit, emit_for, emit_logged, Level, Logged};
    let level = match level {
        "info" => Level::Info,
        "error" => Level::Error,
        _ => Level::Warn,
    };
    match (node, caller) {
        (_, Some((file, function, line))) => {
            let msg = text.to_string();
            emit_logged(
                node,
                level,
                Logged {
                    msg,
                    file,
                    function,
                    line,
                },
            );
        }
        (Some(n), None) => emit_for(Some(n), ratelab_core::textlog::now(), level, text),
        (None, None) => emit(level, text),
    }
}

/// The exception of the learner's code last described ([`describe`]), with the line it was
/// described in: what failed a node or a brain, or refused a run (a brain file whose import
/// failed), for a host to chain to its own error ([`take_failure`], [`take_failure_said`]).
/// One for the process: a host runs one run at a time (`ratelab.run` holds a lock).
static LAST_FAILURE: Mutex<Option<(PyErr, String)>> = Mutex::new(None);

/// The Python exception last described ([`describe`]) since the last call, taken: the
/// learner's code's own error with its traceback, which a host (`ratelab.run`) raises as the
/// cause of its `NodeFailed`. Take it once before a run (to forget an earlier run's) and
/// once after.
pub fn take_failure() -> Option<PyErr> {
    take_failure_said().map(|(e, _)| e)
}

/// [`take_failure`], with the one line [`describe`] said of it: a host chains the exception
/// to an error of its own only when that error says this line (a refusal for it), never to
/// an unrelated one that came after it.
pub fn take_failure_said() -> Option<(PyErr, String)> {
    LAST_FAILURE
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .take()
}

/// One line for a Python exception raised by code of `script` (see the module docs). The
/// exception is kept for [`take_failure`].
pub fn describe(py: Python<'_>, err: &PyErr, script: &str) -> String {
    described(py, err, script).1
}

/// [`describe`], returning the exception it kept as well: `err` from the learner's first
/// frame ([`from_the_learners_frame`]).
fn described(py: Python<'_>, err: &PyErr, script: &str) -> (PyErr, String) {
    let err = from_the_learners_frame(py, err);
    let line = described_line(py, &err, script);
    *LAST_FAILURE.lock().unwrap_or_else(|e| e.into_inner()) =
        Some((err.clone_ref(py), line.clone()));
    (err, line)
}

/// `err` (a new handle on the same exception) with its traceback starting at the first
/// frame that is not ratelab's own
/// support code (`<ratelab>`, the wrapper that called the learner's function): what a
/// learner debugs into (`NodeFailed.__cause__`, `%debug`, the lab's log pane) begins at
/// their own line, as an exception raised by a function they called themselves would.
/// Frames of ratelab's below theirs (a call they made into ratelab) are kept, and so is the
/// whole traceback of an exception raised in ratelab's code alone.
fn from_the_learners_frame(py: Python<'_>, err: &PyErr) -> PyErr {
    let err = err.clone_ref(py);
    let mut tb = err.traceback(py);
    // A traceback is a chain as long as the stack was deep; Python's recursion limit bounds it.
    while let Some(t) = tb.as_ref() {
        let ours = t
            .getattr("tb_frame")
            .and_then(|f| f.getattr("f_code"))
            .and_then(|c| c.getattr("co_filename"))
            .and_then(|n| n.extract::<String>())
            .is_ok_and(|n| n == SUPPORT_FILE_NAME);
        if !ours {
            break;
        }
        tb = t
            .getattr("tb_next")
            .ok()
            .and_then(|n| n.cast_into::<pyo3::types::PyTraceback>().ok());
    }
    // An exception of ratelab's own (a brain's result refused) keeps its frames.
    if tb.is_some() {
        err.set_traceback(py, tb);
    }
    err
}

/// [`describe`]'s line, made printable.
fn described_line(py: Python<'_>, err: &PyErr, script: &str) -> String {
    let described = support(py).ok().and_then(|m| {
        // The traceback goes separately: before Python 3.12 a fetched exception's
        // `__traceback__` is not always set.
        m.call_method1("describe", (err.value(py), script, err.traceback(py)))
            .and_then(|s| s.extract::<String>())
            .ok()
    });
    // The file names in it come from a graph file or a flag: nothing reaches a terminal raw.
    let line = described.unwrap_or_else(|| format!("{script}: {err}"));
    let line = match hung_for(py, err) {
        // A callback that never returned, stopped by Ctrl-C: say it hung, and where it was.
        Some(ran) => format!(
            "{}ran {:.1} s without returning; Ctrl-C interrupted it at {}",
            ratelab_core::metrics::HUNG,
            ran.as_secs_f64(),
            line.strip_suffix(": KeyboardInterrupt").unwrap_or(&line)
        ),
        None => line,
    };
    ratelab_core::text::printable(&line).into_owned()
}

/// Set by [`log_failures`].
static FAILURE_ENTRIES: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// From now on (`on`), say each exception a callback raises (a Python node's tick, a brain's
/// call) in the run's text log as well: one line, its description, carrying the learner's
/// frames and the whole traceback (`ratelab::textlog::emit_failure`), which the terminal
/// lab's log pane shows. Off (the default), a failure is said once, where the run ends (a
/// headless run's summary, the Python package's exception).
pub fn log_failures(on: bool) {
    FAILURE_ENTRIES.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// [`describe`] of an exception `err` a callback of `script` raised (the calling thread is
/// in its node's tick, [`ratelab_core::textlog::enter`]); with [`log_failures`] on, also said in
/// the run's text log with its traceback.
pub(crate) fn describe_failure(py: Python<'_>, err: &PyErr, script: &str) -> String {
    let (err, line) = described(py, err, script);
    if FAILURE_ENTRIES.load(std::sync::atomic::Ordering::Relaxed) {
        ratelab_core::textlog::emit_failure(&line, traceback_of(py, &err, script));
    }
    line
}

/// The learner's frames of `err` (raised by code of `script`) and its whole traceback, as
/// `support.py`'s `traceback_of` gives them (none when it cannot).
fn traceback_of(py: Python<'_>, err: &PyErr, script: &str) -> ratelab_core::textlog::Traceback {
    type Frames = Vec<(String, u32, String, String)>;
    let got = support(py).ok().and_then(|m| {
        m.call_method1("traceback_of", (err.value(py), script, err.traceback(py)))
            .and_then(|t| t.extract::<(Frames, Vec<String>)>())
            .ok()
    });
    let Some((frames, lines)) = got else {
        return ratelab_core::textlog::Traceback::default();
    };
    ratelab_core::textlog::Traceback {
        frames: frames
            .into_iter()
            .map(
                |(file, line, function, code)| ratelab_core::textlog::Frame {
                    file,
                    line,
                    function,
                    code,
                },
            )
            .collect(),
        lines,
    }
}

/// How long this thread's call into learners' code had run when [`interrupt_callbacks`]
/// interrupted it, if `err` is that interruption and the call had run [`HUNG_AFTER`] or
/// longer, or the watchdog had already said it has not returned: a hung callback, not a
/// slow one (a Ctrl-C that answers "has not returned after 0.5 s" stops a hang).
fn hung_for(py: Python<'_>, err: &PyErr) -> Option<Duration> {
    if !err.is_instance_of::<pyo3::exceptions::PyKeyboardInterrupt>(py) {
        return None;
    }
    // SAFETY: PyThread_get_thread_ident only reads the calling thread's id.
    let thread = unsafe { pyo3::ffi::PyThread_get_thread_ident() } as u64;
    let running = lock_running();
    let call = running.get(&thread).filter(|r| r.interrupted)?;
    let ran = call.since.elapsed();
    (ran >= HUNG_AFTER || call.warned).then_some(ran)
}

/// How long a call into learners' code runs without returning (wall time) before it is
/// called hung: the lab's `HUNG` verdict, and what a Ctrl-C that interrupts it says. Far past
/// any tick a balancing graph can afford (its period is 20 ms), and soon enough that a
/// learner sees it at once.
pub const HUNG_AFTER: Duration = Duration::from_secs(1);

thread_local! {
    /// The calling thread tries saved code beside the live run ([`enter_trial`]).
    static TRIAL: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Mark the calling thread, for the rest of its life, as one that tries saved code beside
/// the live run: the lab's reload on save loads the saved code (its import) and runs its
/// trial on a thread of its own, never on the one that runs the live graph. Its calls into
/// learners' code are then not the live run's: [`running_callbacks`] leaves them out (the
/// lab would show one as the live node's hung callback) and the watchdog does not warn of
/// them (the lab's engine says a trial that does not return, naming the file saved).
/// Returns the thread's id for [`interrupt_trial`]. Needs no interpreter.
pub fn enter_trial() -> u64 {
    TRIAL.with(|t| t.set(true));
    // SAFETY: PyThread_get_thread_ident only reads the calling thread's id.
    unsafe { pyo3::ffi::PyThread_get_thread_ident() as u64 }
}

/// Raise `KeyboardInterrupt` in the call into learners' code that thread `thread` runs, if
/// it runs one (a trial superseded by a newer save, [`enter_trial`]); returns whether it
/// did. The caller never waits for the interpreter (whose lock a busy loop holds for up to
/// its switch interval, and C code for as long as it runs): the exception is raised from a
/// thread of its own. It takes effect at the call's next Python instruction, so a call in
/// `time.sleep` or in C code ends that first.
pub fn interrupt_trial(thread: u64) -> bool {
    if SUPPORT.get().is_none() {
        return false;
    }
    match lock_running().get_mut(&thread) {
        Some(r) => r.interrupted = true,
        None => return false,
    }
    let raised = std::thread::Builder::new()
        .name("interrupt-trial".into())
        .spawn(move || {
            Python::attach(|py| {
                let exc = py.get_type::<pyo3::exceptions::PyKeyboardInterrupt>();
                // SAFETY: attached to the interpreter; an id that no longer runs is ignored.
                unsafe {
                    pyo3::ffi::PyThreadState_SetAsyncExc(thread as _, exc.as_ptr());
                }
            });
        });
    raised.is_ok()
}

/// Raise `KeyboardInterrupt` in every call into learners' code of the live run (a trial's,
/// [`enter_trial`], is not one) that has run `at_least` without returning: the lab's first
/// Ctrl-C, which interrupts a hung callback as Ctrl-C does in a headless run (the call fails
/// its node, saying where it was: [`describe`]). Returns who was interrupted, as the
/// warnings name them (`node 'policy' (p.py)`); empty when no call had hung. The caller
/// never waits for the interpreter: the exception is raised from a thread of its own (a busy
/// loop holds the interpreter's lock for up to its switch interval, C code for as long as it
/// runs).
pub fn interrupt_hung_callbacks(at_least: Duration) -> Vec<String> {
    if SUPPORT.get().is_none() {
        return Vec::new();
    }
    let mut who = Vec::new();
    let threads: Vec<u64> = lock_running()
        .iter_mut()
        .filter(|(_, r)| !r.trial && r.since.elapsed() >= at_least)
        .map(|(t, r)| {
            r.interrupted = true;
            who.push(r.what.clone());
            *t
        })
        .collect();
    if threads.is_empty() {
        return who;
    }
    let _ = std::thread::Builder::new()
        .name("interrupt-hung".into())
        .spawn(move || {
            Python::attach(|py| {
                let exc = py.get_type::<pyo3::exceptions::PyKeyboardInterrupt>();
                for t in threads {
                    // SAFETY: attached to the interpreter; an id that no longer runs is
                    // ignored.
                    unsafe {
                        pyo3::ffi::PyThreadState_SetAsyncExc(t as _, exc.as_ptr());
                    }
                }
            });
        });
    who
}

/// Whether a call into learners' code of a save's trial ([`enter_trial`]) has run
/// `at_least` without returning: not the live run's, which the lab's first Ctrl-C then says
/// (a newer save cancels the trial, [`interrupt_trial`]).
pub fn trial_hung(at_least: Duration) -> bool {
    lock_running()
        .values()
        .any(|r| r.trial && r.since.elapsed() >= at_least)
}

/// A call into learners' code in progress: what the watchdog knows of it.
struct Running {
    /// Who is called (`brain policy.py:act`), for the messages.
    what: String,
    /// The node whose tick it is, or whose script loads (`None`: a brain's call or the
    /// loading of a brain's script).
    node: Option<String>,
    /// When the call started.
    since: Instant,
    /// How long it may run before it is reported, and how to say so (`2 s`, or `0.5 s,
    /// 100 of its periods`).
    overrun: Duration,
    overrun_text: String,
    /// Already reported as overrunning.
    warned: bool,
    /// Interrupted by [`interrupt_callbacks`] (Ctrl-C), [`interrupt_hung_callbacks`] (the
    /// lab's Ctrl-C) or [`interrupt_trial`].
    interrupted: bool,
    /// A trial's call, beside the live run ([`enter_trial`]).
    trial: bool,
    /// A script's loading (its module's top level runs), not a tick or a brain's call.
    loading: bool,
}

/// Calls in progress, by Python thread id.
fn running() -> &'static Mutex<HashMap<u64, Running>> {
    static RUNNING: OnceLock<Mutex<HashMap<u64, Running>>> = OnceLock::new();
    RUNNING.get_or_init(Default::default)
}

fn lock_running() -> std::sync::MutexGuard<'static, HashMap<u64, Running>> {
    running().lock().unwrap_or_else(|e| e.into_inner())
}

/// Who the calling thread is running, as the warnings say it (`node 'policy' (p.py)`, `the
/// brain b.py:act()`), and whether that call is a script's loading (its top level running),
/// if it is inside a call into learners' code of a run ([`CallbackGuard`]); `None`
/// otherwise. The Python package refuses a `ratelab.run` from there: the outer run holds
/// the process's one run (its text log and node classes) until its callbacks return.
pub fn callback_of_this_thread() -> Option<(String, bool)> {
    // SAFETY: PyThread_get_thread_ident only reads the calling thread's id.
    let thread = unsafe { pyo3::ffi::PyThread_get_thread_ident() } as u64;
    lock_running()
        .get(&thread)
        .map(|r| (r.what.clone(), r.loading))
}

/// The call into learners' code of a run (not a trial's) that is joining the calling
/// Python thread with no timeout (inside `threading.Thread.join` on it, read from
/// `sys._current_frames()` by the support module's `joining`), as the warnings name it;
/// `None` when none is (or no run has called into Python yet). The Python package asks
/// this while a run waits for the process's one run: a callback that started a thread
/// which calls `ratelab.run`, then joins it, holds the run the thread waits for, and
/// neither could go on. A callback waiting for the thread by other means (a queue, an
/// event) is not seen.
///
/// # Errors
/// What is not an `Exception` that the look raised (a KeyboardInterrupt from a signal
/// handler that ran meanwhile): the caller's to raise. An `Exception` is taken as "none".
pub fn callback_joining_this_thread(py: Python<'_>) -> PyResult<Option<String>> {
    let calls: Vec<(u64, String)> = lock_running()
        .iter()
        .filter(|(_, r)| !r.trial)
        .map(|(t, r)| (*t, r.what.clone()))
        .collect();
    if calls.is_empty() {
        return Ok(None);
    }
    let support = match SUPPORT.get() {
        Some(Ok(m)) => m.bind(py),
        _ => return Ok(None),
    };
    // SAFETY: PyThread_get_thread_ident only reads the calling thread's id.
    let me = unsafe { pyo3::ffi::PyThread_get_thread_ident() } as u64;
    let threads: Vec<u64> = calls.iter().map(|c| c.0).collect();
    let joining: Option<u64> = match support
        .call_method1("joining", (threads, me))
        .and_then(|r| r.extract())
    {
        Ok(t) => t,
        Err(e) if e.is_instance_of::<pyo3::exceptions::PyException>(py) => None,
        Err(e) => return Err(e),
    };
    Ok(joining.and_then(|t| calls.into_iter().find(|c| c.0 == t).map(|c| c.1)))
}

/// Registers a call into learners' code for the watchdog and for [`interrupt_callbacks`];
/// unregisters it when dropped. Create it while attached to the interpreter.
pub struct CallbackGuard {
    thread: u64,
}

impl CallbackGuard {
    /// Register the calling thread as running `what`, reported if it runs
    /// [`OVERRUN_WARNING`] without returning.
    pub fn enter(what: &str) -> CallbackGuard {
        Self::enter_with(
            what,
            None,
            OVERRUN_WARNING,
            format!("{} s", OVERRUN_WARNING.as_secs_f64()),
            false,
        )
    }

    /// Register the calling thread as loading a script (its module's top level runs):
    /// `node`'s (`None`: a brain's script), reported if it runs [`OVERRUN_WARNING`] without
    /// returning. A load that never returns (a sleep or a loop at module level) is then
    /// seen as its node's, as a tick that never returns is ([`Callback::loading`]).
    pub fn enter_loading(what: &str, node: Option<&str>) -> CallbackGuard {
        Self::enter_with(
            what,
            node,
            OVERRUN_WARNING,
            format!("{} s", OVERRUN_WARNING.as_secs_f64()),
            true,
        )
    }

    /// Register the calling thread as running a tick of a node whose period is `period`:
    /// reported after [`OVERRUN_PERIODS`] periods without returning.
    pub fn enter_tick(what: &str, node: &str, period: ratelab_core::time::Nanos) -> CallbackGuard {
        let overrun = Duration::from_nanos(period.0.saturating_mul(u64::from(OVERRUN_PERIODS)));
        Self::enter_with(
            what,
            Some(node),
            overrun,
            format!(
                "{} s, {OVERRUN_PERIODS} of its {period} periods",
                overrun.as_secs_f64()
            ),
            false,
        )
    }

    fn enter_with(
        what: &str,
        node: Option<&str>,
        overrun: Duration,
        overrun_text: String,
        loading: bool,
    ) -> CallbackGuard {
        // SAFETY: PyThread_get_thread_ident only reads the calling thread's id.
        let thread = unsafe { pyo3::ffi::PyThread_get_thread_ident() } as u64;
        lock_running().insert(
            thread,
            Running {
                what: what.to_string(),
                node: node.map(str::to_string),
                since: Instant::now(),
                overrun,
                overrun_text,
                warned: false,
                interrupted: false,
                trial: TRIAL.with(std::cell::Cell::get),
                loading,
            },
        );
        CallbackGuard { thread }
    }
}

impl Drop for CallbackGuard {
    fn drop(&mut self) {
        lock_running().remove(&self.thread);
    }
}

/// A call into a learner's code that has not returned yet ([`running_callbacks`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Callback {
    /// Who is called, as the warnings say it (`node 'policy' (mine.py)`, `the brain
    /// b.py:act()`).
    pub what: String,
    /// The node whose tick it is, or whose script loads; `None` for a brain's call or the
    /// loading of a brain's script (the node that runs the run's brain:
    /// [`ratelab_runtime::graph::kind::KindDef::uses_brain`]).
    pub node: Option<String>,
    /// How long it has run so far (wall time).
    pub running_for: Duration,
    /// A script's loading (its module's top level), not a tick or a brain's call
    /// ([`CallbackGuard::enter_loading`]).
    pub loading: bool,
}

/// The calls into learners' code that have run `at_least` (wall time) without returning,
/// the longest first: what the lab shows as a hung callback (`in callback 3.2 s`, `HUNG`),
/// since under the virtual clock such a call holds the run's clock. A trial's calls beside
/// the live run ([`enter_trial`]) are not the live run's, and are left out.
pub fn running_callbacks(at_least: Duration) -> Vec<Callback> {
    let mut calls: Vec<Callback> = lock_running()
        .values()
        .filter(|r| !r.trial)
        .map(|r| Callback {
            what: r.what.clone(),
            node: r.node.clone(),
            running_for: r.since.elapsed(),
            loading: r.loading,
        })
        .filter(|c| c.running_for >= at_least)
        .collect();
    calls.sort_by_key(|c| std::cmp::Reverse(c.running_for));
    calls
}

/// Warns once (stderr) about each call into learners' code that has overrun by far
/// without returning (see [`CallbackGuard`]).
fn start_watchdog() {
    static STARTED: std::sync::Once = std::sync::Once::new();
    STARTED.call_once(|| {
        let _ = std::thread::Builder::new()
            .name("python-watchdog".into())
            .spawn(|| loop {
                std::thread::sleep(WATCHDOG_POLL);
                // A trial's call is said by the lab's engine, naming the file saved.
                for r in lock_running().values_mut().filter(|r| !r.trial) {
                    if r.since.elapsed() >= r.overrun && !r.warned {
                        r.warned = true;
                        // To the run's text log: the lab's pane, not over its screen.
                        ratelab_core::textlog::emit_for(
                            r.node.as_deref(),
                            None,
                            ratelab_core::textlog::Level::Warn,
                            &format!(
                                "[ratelab] warning: {} has not returned after {} (Ctrl-C interrupts it)",
                                r.what, r.overrun_text
                            ),
                        );
                    }
                }
            });
    });
}

/// How long a Python callback may still run after a stop (Ctrl-C, `q` in the lab) before it
/// is interrupted ([`interrupt_callbacks_after`]), in every front end.
pub const PYTHON_GRACE: Duration = Duration::from_millis(300);

/// [`interrupt_callbacks`]`(grace)` on a thread of its own, `grace` from now: for a stop
/// (Ctrl-C, quitting the lab) that must not wait on a callback that never returns.
pub fn interrupt_callbacks_after(grace: Duration) {
    if SUPPORT.get().is_none() {
        return;
    }
    std::thread::spawn(move || {
        std::thread::sleep(grace);
        interrupt_callbacks(grace);
    });
}

/// Raise `KeyboardInterrupt` inside every call into learners' code that has been running
/// for at least `grace`, so that a callback that never returns cannot hang a run that was
/// asked to stop (Ctrl-C). The interrupted call fails the node as any exception does, its
/// message naming where it was interrupted. Does nothing when no Python code runs.
pub fn interrupt_callbacks(grace: Duration) {
    if SUPPORT.get().is_none() {
        return;
    }
    let threads: Vec<u64> = lock_running()
        .iter_mut()
        .filter(|(_, r)| r.since.elapsed() >= grace)
        .map(|(t, r)| {
            r.interrupted = true;
            *t
        })
        .collect();
    if threads.is_empty() {
        return;
    }
    Python::attach(|py| {
        let exc = py.get_type::<pyo3::exceptions::PyKeyboardInterrupt>();
        for t in threads {
            // SAFETY: attached to the interpreter; an id that no longer runs is ignored.
            unsafe {
                pyo3::ffi::PyThreadState_SetAsyncExc(t as _, exc.as_ptr());
            }
        }
    });
}

/// The message registry as Python's `install_message_module` takes it: per type its name,
/// class, doc, fields `(name, unit, doc, kind)` (`number`, `text` or `bytes`) and ROS 2
/// type.
type RegistryRow = (
    &'static str,
    &'static str,
    &'static str,
    Vec<(&'static str, &'static str, &'static str, &'static str)>,
    Option<&'static str>,
);

fn message_registry() -> Vec<RegistryRow> {
    ratelab_core::msg::registered()
        .into_iter()
        .map(|t| {
            (
                t.as_str(),
                t.class(),
                t.doc(),
                t.fields()
                    .iter()
                    .map(|f| {
                        let kind = match f.kind {
                            ratelab_core::msg::FieldKind::Number => "number",
                            ratelab_core::msg::FieldKind::Integer => "integer",
                            ratelab_core::msg::FieldKind::Text => "text",
                            ratelab_core::msg::FieldKind::Bytes => "bytes",
                        };
                        (f.name, f.unit, f.doc, kind)
                    })
                    .collect(),
                t.ros2().map(|c| (c.ros_type)().name),
            )
        })
        .collect()
}

/// Make `import ratelab` give every registered message type's class (and `Time`), as a
/// Python node sees them ([`ratelab_core::msg`]: the one definition of each type).
///
/// # Errors
/// The support module's error: a built-in class that does not match the registry.
pub fn install_messages(py: Python<'_>) -> PyResult<()> {
    let support =
        support(py).map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
    support.call_method1("install_message_module", (message_registry(),))?;
    Ok(())
}
