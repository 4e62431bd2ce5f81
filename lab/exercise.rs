//! `ratelab exercise ex1|…`: predict, run, reconcile. The exercises themselves are the
//! library's registry ([`ratelab_exercises::EXERCISES`]); this is where their report goes
//! (stdout), their progress (a spinner on stderr) and what their outcome means for the exit
//! code.

use ratelab::run_spec::GraphSettings;
use ratelab::setting::Speech;
use ratelab_exercises::{ExerciseSpec, Progress};
use std::cell::RefCell;

/// An exercise that ran to its end but did not pass: a check failed, or a prediction
/// missed or could not be read. `ratelab exercise` then exits 1 (2 is for what kept it from
/// running).
#[derive(Debug)]
pub struct NotPassed {
    /// Checks that failed (`[!!]` above).
    pub checks_failed: usize,
    /// Predictions that missed or could not be read (the reconcile's `Your prediction:` line
    /// names them).
    pub predictions_missed: usize,
}

impl std::fmt::Display for NotPassed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use ratelab::metrics::counted;
        let mut what = Vec::new();
        if self.predictions_missed > 0 {
            what.push(format!(
                "{} missed or could not be read",
                counted(self.predictions_missed as u64, "prediction")
            ));
        }
        if self.checks_failed > 0 {
            what.push(format!(
                "{} failed",
                counted(self.checks_failed as u64, "check")
            ));
        }
        write!(
            f,
            "{} (see above): the exercise is not passed",
            what.join(" and ")
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

/// `ratelab exercise`: its flags read into the library's [`ExerciseSpec`] (the graph: the
/// chapter's, or the one the exercise's bands name, with the command line's overrides),
/// which runs it, its report on stdout and a spinner on stderr.
///
/// # Errors
/// What kept it from running (bad flags, no prediction, unreadable files or bands), Ctrl-C
/// (`stop`: the run in progress ends, nothing is graded), or [`NotPassed`].
pub fn run_from_args(
    args: &crate::cli::ExerciseArgs,
    stop: &ratelab::scheduler::StopFlag,
) -> anyhow::Result<()> {
    let spec = ExerciseSpec {
        which: args.which.clone(),
        dir: args.dir.clone(),
        graph: GraphSettings::from(&args.graph),
        prediction: None,
    };
    let mut out = |line: &str| println!("{line}");
    let report = spec.report(Speech::Flags, &mut out, &Spinner::default(), stop)?;
    match report.not_passed {
        0 => Ok(()),
        _ => Err(NotPassed {
            checks_failed: report.checks_failed,
            predictions_missed: report.predictions_missed,
        }
        .into()),
    }
}
