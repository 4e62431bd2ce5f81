//! `ratelab._native`, the wheel's extension module: the Python API
//! ([`ratelab_py::register`]: `run`, `sweep`, `cliff`, `exercise`, over the library) and the
//! `ratelab` command the wheel installs (`main`: the command line and the terminal lab,
//! `ratelab-lab`), in one shared library loaded by the user's interpreter. The API does not
//! depend on the command: this crate is where the two meet.
#![warn(missing_docs)]

use pyo3::prelude::*;

/// Run ratelab's command line on `argv` (the program's name first) in this process and
/// return its exit code (0 done, 1 an exercise not passed, 2 bad input or a failed run, 130
/// interrupted). Ctrl-C is ratelab's from then on, as in the binary. A launch's processes
/// are started as `python -m ratelab process …` ([`ratelab_py::hosted`]).
#[pyfunction]
fn main(py: Python<'_>, argv: Vec<String>) -> PyResult<u8> {
    let args = argv.into_iter().map(Into::into).collect();
    // The command's Python output goes to the run's text log, as the binary's does.
    let capture = ratelab::python::capture_output().ok();
    let code = py.detach(|| ratelab_lab::run_command_line(args, || {}));
    drop(capture);
    Ok(code)
}

/// The extension module: the Python API, then the command.
#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    ratelab_py::register(m)?;
    m.add_function(wrap_pyfunction!(main, m)?)?;
    Ok(())
}
