//! ratelab's commands for a program that hosts the command line as a library (the Python
//! package, `src/py`): `exercise` from its flags, its report returned, nothing printed. A
//! single run is the library's, from its `RunSpec` ([`run`], re-exported from
//! `ratelab::held_run`), and so are a sweep and a cliff search, from their
//! `ratelab::sweep_spec::{SweepSpec, CliffSpec}`.

use crate::cli::{Cli, Command};

// A run from its `RunSpec`, its results in memory: the library's (`ratelab::held_run`).
pub use ratelab::held_run::{check_held_trace, run, RunFiles, TraceTooLarge};

/// `ratelab SUBCOMMAND FLAGS…` read as the command line reads it.
fn parse(subcommand: &str, flags: &[String]) -> anyhow::Result<Command> {
    let argv = ["ratelab", subcommand]
        .into_iter()
        .map(String::from)
        .chain(flags.iter().cloned());
    let cli =
        Cli::parse_argv(argv).map_err(|e| anyhow::anyhow!(crate::one_line(&e.to_string())))?;
    cli.command.ok_or_else(|| anyhow::anyhow!("no subcommand"))
}

/// What `ratelab exercise` found, and the report it printed.
#[derive(Clone, Debug)]
pub struct ExerciseOutcome {
    /// Its checks, reconcile sentences and what did not pass.
    pub report: ratelab_exercises::Report,
    /// The report as `ratelab exercise` prints it, a line each.
    pub lines: Vec<String>,
}

/// `ratelab exercise WHICH FLAGS…` (`--dir`, `--graph`, …), with `prediction_json` (a JSON
/// object: the keys the exercise's file asks for, and `why`) in place of the learner's
/// file's prediction when given. Nothing is printed.
///
/// # Errors
/// Bad flags, a prediction that is not a JSON object of TOML values, no prediction, an
/// exercise that cannot run (unreadable files or bands, a run that cannot start).
pub fn exercise(
    which: &str,
    flags: &[String],
    prediction_json: Option<&str>,
) -> anyhow::Result<ExerciseOutcome> {
    let all: Vec<String> = std::iter::once(which.to_string())
        .chain(flags.iter().cloned())
        .collect();
    let Command::Exercise(a) = parse("exercise", &all)? else {
        anyhow::bail!("not an exercise");
    };
    let prediction: Option<toml::Table> = prediction_json
        .map(serde_json::from_str)
        .transpose()
        .map_err(|e| anyhow::anyhow!("prediction: {e}"))?;
    let mut lines = Vec::new();
    let mut out = |text: &str| lines.extend(text.lines().map(str::to_string));
    let report = crate::exercise::report_from_args(&a, prediction.as_ref(), &mut out, &())?;
    Ok(ExerciseOutcome { report, lines })
}
