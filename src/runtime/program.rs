//! How this process's own command line is started again, in another process: the
//! launcher's processes (`ratelab process …`) and a camera's renderer (`ratelab
//! render-camera …`) run as ratelab's command line does. The `ratelab` binary is itself;
//! a program built on the command line library (`ratelab_lab::main_with`) is itself too;
//! inside a Python interpreter it is `python -m ratelab`, set when the package is imported
//! ([`Program::set_this`]).

use std::path::PathBuf;

/// A program that runs ratelab's command line: the executable and the arguments that come
/// before the subcommand. The `ratelab` binary is itself with none; installed from the
/// Python wheel it is `python -m ratelab` ([`Program::set_this`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Program {
    /// The executable.
    pub path: PathBuf,
    /// Its arguments before ratelab's subcommand (`["-m", "ratelab"]`).
    pub args: Vec<std::ffi::OsString>,
}

/// Set by [`Program::set_this`]: how this process's own command line is started again.
static THIS_PROGRAM: std::sync::OnceLock<Program> = std::sync::OnceLock::new();

impl Program {
    /// This process's own command line: what [`Program::set_this`] set, else the running
    /// executable with no arguments before the subcommand.
    ///
    /// # Errors
    /// When the running executable's path cannot be read.
    pub fn this() -> std::io::Result<Program> {
        match THIS_PROGRAM.get() {
            Some(p) => Ok(p.clone()),
            None => Ok(Program::from(std::env::current_exe()?)),
        }
    }

    /// What [`Program::set_this`] set, and nothing else: `Some` only where this process is
    /// known to run ratelab's command line (the `ratelab` binary, a
    /// `ratelab_lab::main_with` program, the Python package). A program that only links the
    /// library has none, and nothing starts it again with ratelab's subcommands.
    pub fn this_if_set() -> Option<Program> {
        THIS_PROGRAM.get().cloned()
    }

    /// Say how this process's command line is started again, when it is not the running
    /// executable alone (ratelab inside a Python interpreter: `python -m ratelab`). The first
    /// call wins; returns false when one was set already.
    pub fn set_this(program: Program) -> bool {
        THIS_PROGRAM.set(program).is_ok()
    }

    /// A command that runs the program, its leading arguments given.
    pub fn command(&self) -> std::process::Command {
        let mut cmd = std::process::Command::new(&self.path);
        cmd.args(&self.args);
        cmd
    }
}

impl From<PathBuf> for Program {
    fn from(path: PathBuf) -> Self {
        Program {
            path,
            args: Vec::new(),
        }
    }
}
