//! Code in another language that a graph runs: a learner's Python, as a node
//! (`kind = "python"`) or as a brain (`--policy FILE.py[:FUNCTION]`). The runtime knows
//! their graph-file and command-line forms; running them is the Python layer's
//! (`ratelab_python`, above this crate, so that changing it rebuilds neither the runtime
//! nor anything beside it), which installs itself here ([`install`]). The `ratelab`
//! facade's `init()` installs it, and the command line calls that first; a Rust program
//! that runs Python nodes or brains through the library calls it too. Without it, a graph
//! with a Python node or a Python brain is refused in one line ([`NOT_INSTALLED`]).

use crate::graph::kind::{BuildContext, NodeOf, PythonCode};
use crate::policy::Policy;
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::sync::{Arc, OnceLock};

/// The function a `--policy FILE.py` brain runs when none is named.
pub const DEFAULT_FUNCTION: &str = "act";

/// What a Python node or brain meets when no interpreter is installed.
pub const NOT_INSTALLED: &str =
    "Python nodes and brains need ratelab's Python layer: call ratelab::init() first (the command line does)";

/// Why a Python brain cannot be loaded ([`Interpreter::brain`]): the one line, and whether
/// it is because the script is not there (`missing`), which a front end tells apart as a
/// checkpoint's missing file is (`crate::checkpoint::PolicyError::NotFound`, Python's
/// `FileNotFoundError`).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{line}")]
pub struct BrainLoadError {
    /// The one-line reason.
    pub line: String,
    /// The script is not there.
    pub missing: bool,
}

/// Runs a learner's Python: implemented by the Python layer (`ratelab_python`).
pub trait Interpreter: Send + Sync {
    /// The work of node `cx.name` of kind `python`, running `code`.
    ///
    /// # Errors
    /// The one-line reason it cannot start (the script unreadable, raising at import, a
    /// class or publisher that does not fit the graph file).
    fn node(&self, cx: &mut BuildContext<'_>, code: &PythonCode) -> Result<NodeOf, String>;

    /// The brain that calls `function` of `script` once per control tick.
    ///
    /// # Errors
    /// [`BrainLoadError`]: the one-line reason it cannot be loaded, and whether the script
    /// is not there.
    fn brain(&self, script: &str, function: &str) -> Result<Box<dyn Policy>, BrainLoadError>;

    /// Mark the calling thread, for the rest of its life, as one that tries saved code
    /// beside the live run (the lab's reload on save loads the saved code, and runs its
    /// trial, on a thread of its own): its calls into learners' code are not the live run's
    /// (the lab shows none of them as a live node's hung callback). Returns the thread's id
    /// for [`Interpreter::interrupt_trial`]; 0 (the default): none.
    fn enter_trial(&self) -> u64 {
        0
    }

    /// Raise `KeyboardInterrupt` in the call into learners' code that the trial thread
    /// `thread` ([`Interpreter::enter_trial`]) is running, if it runs one, without waiting
    /// for the interpreter; returns whether it ran one. The default interrupts nothing.
    fn interrupt_trial(&self, thread: u64) -> bool {
        let _ = thread;
        false
    }
}

static INSTALLED: OnceLock<&'static dyn Interpreter> = OnceLock::new();

/// Install the interpreter Python nodes and brains run in, once per process (a second call
/// keeps the first).
pub fn install(interpreter: &'static dyn Interpreter) {
    let _ = INSTALLED.set(interpreter);
}

/// The interpreter installed ([`install`]).
///
/// # Errors
/// [`NOT_INSTALLED`] when none is.
pub fn installed() -> Result<&'static dyn Interpreter, String> {
    INSTALLED
        .get()
        .copied()
        .ok_or_else(|| NOT_INSTALLED.to_string())
}

/// Learners' scripts by the path they were read from, their text as read: what a thread
/// read ([`scripts_read`]), or what it is to read instead of the files ([`pin_scripts`]).
pub type Scripts = BTreeMap<String, Arc<str>>;

thread_local! {
    /// Every script the thread read, as it last read it.
    static READ: RefCell<Scripts> = const { RefCell::new(BTreeMap::new()) };
    /// The scripts the thread reads instead of their files, if pinned.
    static PINNED: RefCell<Option<Scripts>> = const { RefCell::new(None) };
}

/// The text of the learner's script `script`, as the calling thread is to read it: the text
/// it is pinned to ([`pin_scripts`]), else what `read` gives (the file as it is now);
/// either way kept as what the thread last read of it ([`scripts_read`]). The Python layer
/// reads every script through this.
///
/// # Errors
/// `read`'s error.
pub fn script_text<E>(
    script: &str,
    read: impl FnOnce() -> Result<String, E>,
) -> Result<Arc<str>, E> {
    let text = match PINNED.with_borrow(|p| p.as_ref().and_then(|p| p.get(script).cloned())) {
        Some(pinned) => pinned,
        None => Arc::from(read()?),
    };
    READ.with_borrow_mut(|r| r.insert(script.to_string(), text.clone()));
    Ok(text)
}

/// Every script the calling thread read ([`script_text`]) since it last forgot them
/// ([`forget_scripts_read`]), each as it last read it. The lab's engine forgets at each
/// run's start, so this is the code of the run on screen (the engine builds it on a thread
/// of its own; a save's trial loads the saved code on another).
pub fn scripts_read() -> Scripts {
    READ.with_borrow(Clone::clone)
}

/// Forget what the calling thread read ([`scripts_read`]).
pub fn forget_scripts_read() {
    READ.with_borrow_mut(BTreeMap::clear);
}

/// The scripts the calling thread is pinned to ([`pin_scripts`]), if it is.
pub fn pinned_scripts() -> Option<Scripts> {
    PINNED.with_borrow(Clone::clone)
}

/// From now on the calling thread reads `scripts` instead of their files (`None`: the files
/// again); a script not among them is read from its file. The lab pins the code of the run
/// on screen from the moment a file is saved, so that what the engine builds meanwhile (a
/// seek's replay) and after a save that is not taken up (it did not load, its trial was
/// dropped) has the code before, as the lab says, until a save is taken up.
pub fn pin_scripts(scripts: Option<Scripts>) {
    PINNED.with_borrow_mut(|p| *p = scripts);
}

/// Does `spec` name a Python brain (`FILE.py` or `FILE.py:FUNCTION`)? Returns the file and
/// the function.
pub fn parse_spec(spec: &str) -> Option<(&str, &str)> {
    if spec.ends_with(".py") {
        return Some((spec, DEFAULT_FUNCTION));
    }
    let (file, function) = spec.rsplit_once(':')?;
    (file.ends_with(".py") && !function.is_empty()).then_some((file, function))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ClockKind, RunConfig};
    use crate::graph::spec::GraphSpec;

    #[test]
    fn a_pinned_script_is_read_as_pinned_and_every_read_is_kept() {
        let disk = |text: &str| {
            let text = text.to_string();
            move || Ok::<_, String>(text)
        };
        assert_eq!(&*script_text("a.py", disk("one")).unwrap(), "one");
        assert_eq!(&*scripts_read()["a.py"], "one");
        // The file changed: read again, and kept.
        assert_eq!(&*script_text("a.py", disk("two")).unwrap(), "two");
        pin_scripts(Some(scripts_read()));
        // Pinned: the file's new text is not read; a script not pinned is.
        assert_eq!(&*script_text("a.py", disk("three")).unwrap(), "two");
        assert_eq!(&*script_text("b.py", disk("b")).unwrap(), "b");
        assert_eq!(
            script_text("c.py", || Err::<String, _>("unreadable")),
            Err("unreadable")
        );
        // Another thread is not pinned.
        std::thread::spawn(move || {
            assert_eq!(&*script_text("a.py", disk("three")).unwrap(), "three");
        })
        .join()
        .unwrap();
        assert!(pinned_scripts().is_some());
        pin_scripts(None);
        assert_eq!(pinned_scripts(), None);
        assert_eq!(&*script_text("a.py", disk("four")).unwrap(), "four");
        forget_scripts_read();
        assert!(scripts_read().is_empty());
    }

    #[test]
    fn a_python_brain_is_spelled_with_its_file_and_function() {
        assert_eq!(parse_spec("b.py"), Some(("b.py", DEFAULT_FUNCTION)));
        assert_eq!(
            parse_spec("dir/b.py:balance"),
            Some(("dir/b.py", "balance"))
        );
        assert_eq!(parse_spec("b.py:"), None);
        assert_eq!(parse_spec("ppo.pt"), None);
        assert_eq!(parse_spec("scripted"), None);
    }

    /// The runtime's own tests install no interpreter: Python is refused in one line.
    #[test]
    fn without_the_python_layer_python_is_refused_in_one_line() {
        let brain = crate::checkpoint::load_policy("graphs/brains/scripted.py");
        assert_eq!(
            brain.err().map(|e| e.to_string()).as_deref(),
            Some(NOT_INSTALLED)
        );
        let text = include_str!("../../../graphs/cartpole-python.toml");
        let cfg = RunConfig {
            graph: GraphSpec::parse(text, "graphs/cartpole-python.toml").unwrap(),
            clock: ClockKind::Virtual,
            ..RunConfig::default()
        };
        let err = crate::runcore::RunCore::new(
            &cfg,
            Box::new(crate::policy::Scripted),
            crate::runcore::CoreOptions::default(),
        )
        .err()
        .expect("a Python node without an interpreter");
        assert!(err.to_string().contains(NOT_INSTALLED), "{err}");
        assert!(!err.to_string().contains('\n'), "{err}");
    }
}
