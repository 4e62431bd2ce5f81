//! A brain written in Python: `--policy FILE.py[:FUNCTION]` runs `FUNCTION(obs) -> action`
//! (default `act`) as the policy node's brain — the chapter's `load_policy` contract, "a
//! function from observation to action".
//!
//! - `obs` is the chapter's observation as a NumPy `float32[5]` array: cart position m,
//!   cart velocity m/s, cos θ, sin θ, pole angular velocity rad/s.
//! - The return value is a float or a one-element array-like (a NumPy array, a list, a
//!   NumPy scalar): the force command in motor units, converted to float32 and clipped to
//!   [−1, 1] as the chapter's environment does (×10 N on the cart). A NaN or ±inf passes
//!   through unclipped and the actuator refuses it, holding its last good force; `None` (or
//!   anything else that is not one number) fails the node.
//! - Under the virtual clock a brain that does the chapter's arithmetic gives exactly the
//!   chapter's run: Python floats are IEEE doubles and `math` calls the same C library.
//!
//! Errors, one line each: the file missing or unreadable, a syntax error (`FILE:LINE`), an
//! exception while the module loads, no such function, NumPy missing; during the run an
//! exception or a wrong return value fails the policy node at that tick (see
//! `ratelab::python`).

use super::{
    describe, describe_failure, start, support, CallbackGuard, PythonError, MAX_SCRIPT_BYTES,
};
use pyo3::prelude::*;
use ratelab_core::plant::{Action, Observation};
use ratelab_runtime::policy::Policy;
use std::sync::atomic::{AtomicU64, Ordering};

pub use ratelab_runtime::graph::interpreter::{parse_spec, DEFAULT_FUNCTION};

/// The cost of calling into Python once per tick, as `ratelab bench` reports it: `calls`
/// calls of an empty brain (`def act(obs): return 0.0`) through [`PythonBrain`] (the
/// observation made a NumPy array, the call, the return value converted), each timed.
/// Returns the per-call times in nanoseconds, p50 and p99.
///
/// # Errors
/// [`PythonError`] when the interpreter or NumPy is not available.
pub fn call_cost(calls: usize) -> Result<(u64, u64), PythonError> {
    let mut brain = PythonBrain::from_source("<bench>", "def act(obs):\n    return 0.0\n", "act")?;
    let mut times = ratelab_core::metrics::LatencyStats::default();
    let obs = [0.0, 0.0, 1.0, 0.0, 0.0];
    for _ in 0..calls.max(1) {
        let start = std::time::Instant::now();
        std::hint::black_box(brain.act(std::hint::black_box(&obs)));
        times.record(ratelab_core::time::Nanos::from(start.elapsed()));
    }
    let q = |p: f64| times.quantile(p).map_or(0, |n| n.0);
    Ok((q(0.5), q(0.99)))
}

/// A brain that calls a Python function (see the module docs).
pub struct PythonBrain {
    call: Py<PyAny>,
    /// The file its code is in, for tracebacks.
    script: String,
    /// How the run names it (`FILE.py:FUNCTION`; `act in a notebook cell`).
    shown: String,
    /// What a message says is running: `the brain FILE.py:FUNCTION()`.
    what: String,
}

impl PythonBrain {
    /// Load `function` from the Python file `script`.
    ///
    /// # Errors
    /// [`PythonError`]: see the module docs.
    pub fn load(script: &str, function: &str) -> Result<PythonBrain, PythonError> {
        let source = read_script(script)?;
        PythonBrain::from_source(script, &source, function)
    }

    /// Load `function` from Python `source`, named `script` in messages and tracebacks.
    ///
    /// # Errors
    /// [`PythonError`] as [`PythonBrain::load`], but for reading the file.
    pub fn from_source(
        script: &str,
        source: &str,
        function: &str,
    ) -> Result<PythonBrain, PythonError> {
        start()?;
        static LOADED: AtomicU64 = AtomicU64::new(0);
        let module_name = format!("ratelab_brain_{}", LOADED.fetch_add(1, Ordering::Relaxed));
        Python::attach(|py| {
            let support = support(py)?;
            let loaded = {
                let _running = CallbackGuard::enter_loading(&format!("loading {script}"), None);
                // `import ratelab` gives the message classes, as in a node's script.
                super::install_messages(py).and_then(|()| {
                    support.call_method1("load_module", (script, source, module_name))
                })
            };
            let module = loaded.map_err(|e| PythonError::Script(describe(py, &e, script)))?;
            let call = support
                .call_method1("brain_caller", (module, function, script))
                .map_err(|e| match e.is_instance_of::<pyo3::exceptions::PyImportError>(py) {
                    true => PythonError::Interpreter(format!(
                        "{script}: a Python brain gets its observation as a NumPy array, and NumPy cannot be imported ({}); install it (python3 -m pip install numpy) or activate a virtual environment that has it",
                        e.value(py)
                    )),
                    false => PythonError::Script(describe(py, &e, script)),
                })?;
            Ok(PythonBrain {
                call: call.unbind(),
                script: script.to_string(),
                shown: format!("{script}:{function}"),
                what: format!("the brain {script}:{function}()"),
            })
        })
    }
}

impl PythonBrain {
    /// A brain of the function object `function` the caller holds (`ratelab.run(policy=fn)`
    /// in a notebook): called as a `FILE.py:FUNCTION` brain is, so the same code gives
    /// exactly the same run. Named by the file and name of its code, or, where its code has
    /// no file (a notebook cell, the interpreter), by its name and where it was typed.
    ///
    /// # Errors
    /// [`PythonError::Script`] when it is not callable; [`PythonError::Interpreter`] without
    /// NumPy.
    pub fn from_callable(function: Py<PyAny>) -> Result<PythonBrain, PythonError> {
        start()?;
        Python::attach(|py| {
            let made = support(py)?
                .call_method1("callable_brain", (function,))
                .and_then(|t| t.extract::<(Py<PyAny>, String, String)>());
            let (call, script, shown) = made.map_err(|e| {
                match e.is_instance_of::<pyo3::exceptions::PyImportError>(py) {
                    true => PythonError::Interpreter(format!(
                        "a Python brain gets its observation as a NumPy array, and NumPy cannot be imported ({})",
                        e.value(py)
                    )),
                    false => PythonError::Script(describe(py, &e, "policy")),
                }
            })?;
            Ok(PythonBrain {
                call,
                what: format!("the brain {shown}"),
                script,
                shown,
            })
        })
    }
}

/// Read a learner's script: a regular file, bounded, UTF-8 (Python's default encoding);
/// or the text the calling thread is pinned to ([`ratelab_runtime::graph::interpreter::script_text`]).
pub(crate) fn read_script(script: &str) -> Result<String, PythonError> {
    ratelab_runtime::graph::interpreter::script_text(script, || read_script_file(script))
        .map(|text| text.to_string())
}

/// Read a learner's script from its file: a regular file, bounded, UTF-8.
fn read_script_file(script: &str) -> Result<String, PythonError> {
    let bytes =
        ratelab_core::input::read_regular_file(std::path::Path::new(script), MAX_SCRIPT_BYTES)
            .map_err(|e| {
                let line = format!("cannot read Python script {e}");
                let line = match e {
                    ratelab_core::input::InputError::TooLarge { .. } => {
                        ratelab_core::limits::refusal(line, "MAX_SCRIPT_BYTES")
                    }
                    _ => line,
                };
                PythonError::Input {
                    line,
                    missing: matches!(e, ratelab_core::input::InputError::NotFound(_)),
                }
            })?;
    ratelab_core::input::utf8_text(bytes).map_err(|e| PythonError::Input {
        line: format!(
            "{script}:{}: not UTF-8 text (byte {:#04x} at column {})",
            e.line, e.byte, e.col
        ),
        missing: false,
    })
}

impl Policy for PythonBrain {
    /// # Panics
    /// When the function raises or returns something that is not one number: the panic's
    /// message is the one-line description, and the scheduler fails the node with it.
    fn act(&mut self, obs: &Observation) -> Action {
        let result = Python::attach(|py| {
            let _running = CallbackGuard::enter(&self.what);
            let obs = obs.map(f64::from);
            self.call
                .call1(py, (obs,))
                .and_then(|v| v.extract::<f64>(py))
                .map_err(|e| describe_failure(py, &e, &self.script))
        });
        match result {
            // f64 of a float32 is exact, and so is the way back. A non-finite command
            // (NaN, ±inf) is not clipped: the actuator refuses it and holds its last good
            // force, and the run counts and says it (inf is no full push).
            Ok(u) => {
                let u = u as f32;
                [if u.is_finite() { u.clamp(-1.0, 1.0) } else { u }]
            }
            Err(message) => panic!("{message}"),
        }
    }

    fn label(&self) -> String {
        format!("Python brain {}", self.shown)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_names_a_file_and_a_function() {
        assert_eq!(parse_spec("b.py"), Some(("b.py", "act")));
        assert_eq!(parse_spec("dir/b.py:policy"), Some(("dir/b.py", "policy")));
        assert_eq!(parse_spec("b.py:"), None);
        assert_eq!(parse_spec("b.onnx"), None);
        assert_eq!(parse_spec("scripted"), None);
        assert_eq!(parse_spec("c:/x.pt"), None);
    }
}
