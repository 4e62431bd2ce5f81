//! `ratelab exercise ex1|…`: predict, run, reconcile. The exercises themselves are the
//! library's registry ([`ratelab::exercise::EXERCISES`]); this is where their report goes
//! (stdout), their progress (a spinner on stderr) and what their outcome means for the exit
//! code.

use anyhow::bail;
use ratelab::exercise::{Progress, Setup};
use std::cell::RefCell;
use std::path::Path;

/// An exercise that ran to its end but did not pass: a check failed or a prediction could
/// not be read. `ratelab exercise` then exits 1 (2 is for what kept it from running).
#[derive(Debug)]
pub struct NotPassed(pub usize);

impl std::fmt::Display for NotPassed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} check(s) or prediction(s) did not pass (marked above): the exercise is not passed",
            self.0
        )
    }
}

impl std::error::Error for NotPassed {}

/// A spinner and the elapsed time on stderr while an exercise measures (when stderr is a
/// terminal): the measurements take from seconds to a minute.
#[derive(Default)]
struct Spinner(RefCell<Option<indicatif::ProgressBar>>);

impl Progress for Spinner {
    fn begin(&self, what: &str) {
        use std::io::IsTerminal;
        *self.0.borrow_mut() = std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new_spinner();
            bar.set_style(
                indicatif::ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
                    .expect("static template"),
            );
            bar.set_message(what.to_string());
            bar.enable_steady_tick(std::time::Duration::from_millis(200));
            bar
        });
    }

    fn end(&self) {
        if let Some(b) = self.0.borrow_mut().take() {
            b.finish_and_clear();
        }
    }
}

/// `ratelab exercise`: the graph (the chapter's, or the one the exercise's bands name, with
/// the command line's overrides), then [`run_exercise`].
pub fn run_from_args(args: &crate::cli::ExerciseArgs) -> anyhow::Result<()> {
    let mut graph = args.graph.clone();
    if graph.graph.is_none() {
        graph.graph = ratelab::exercise::default_graph(&args.which, &args.dir)?;
    }
    let g = crate::headless::graph_from_args(&graph)?;
    if !crate::headless::faults_from_args(&graph).is_empty() {
        bail!("--stall/--kill: the exercises inject no faults; use `ratelab run` or `ratelab lab` with them");
    }
    run_exercise(&args.which, &args.dir, &g, graph.graph.as_deref())
}

/// Run exercise `which` from the exercise folder `dir` on `graph` (read from `graph_path`,
/// `None` for the chapter's: ex9's processes load it too).
///
/// # Errors
/// What kept it from running (exit 2), or [`NotPassed`] after it ran when a check failed or
/// a prediction could not be read (exit 1).
pub fn run_exercise(
    which: &str,
    dir: &Path,
    graph: &ratelab::graph::GraphSpec,
    graph_path: Option<&Path>,
) -> anyhow::Result<()> {
    let exe = ratelab::distributed::launcher::Program::this()?;
    let setup = Setup {
        dir,
        graph,
        graph_path,
        exe: &exe,
    };
    let mut out = |line: &str| println!("{line}");
    match ratelab::exercise::run(which, setup, &mut out, &Spinner::default())? {
        0 => Ok(()),
        n => Err(NotPassed(n).into()),
    }
}
