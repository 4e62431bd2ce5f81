//! ratelab's commands for a program that hosts the command line as a library (the Python
//! package, `src/py`): `sweep`, `cliff` and `exercise` from their flags, their tables and
//! reports returned, nothing printed. A single run is the library's, from its `RunSpec`
//! ([`run`], re-exported from `ratelab::held_run`).

use crate::cli::{Cli, Command};
use ratelab::scheduler::StopFlag;

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

/// `ratelab sweep FLAGS…` until `stop`: its table as `--csv` writes it (a header, then one
/// row per run: the grid's point and the run's figures), and the line of the first run that
/// failed a node, when one did. Nothing is printed.
///
/// # Errors
/// Bad flags or settings, a brain that cannot be loaded, a run that cannot start.
pub fn sweep(flags: &[String], stop: &StopFlag) -> anyhow::Result<(String, Option<String>)> {
    let Command::Sweep(a) = parse("sweep", flags)? else {
        anyhow::bail!("not a sweep");
    };
    let rows = crate::sweep::sweep_rows(&a, stop, false)?;
    let mut csv = Vec::new();
    crate::sweep::write_csv(&mut csv, &rows)?;
    let failed = crate::sweep::sweep_failed(&rows)
        .err()
        .map(|e| e.to_string());
    Ok((String::from_utf8(csv)?, failed))
}

/// `ratelab cliff FLAGS…` until `stop`: per seed, the highest control rate at which the pole
/// falls, as CSV (`seed,falls_at_hz,balances_at_hz,runs`; a rate is empty when there is
/// none). Nothing is printed.
///
/// # Errors
/// Bad flags or settings, a brain that cannot be loaded, a run that cannot start.
pub fn cliff(flags: &[String], stop: &StopFlag) -> anyhow::Result<String> {
    let Command::Cliff(a) = parse("cliff", flags)? else {
        anyhow::bail!("not a cliff search");
    };
    let (cliffs, _, _) = crate::sweep::cliffs(&a, stop, false)?;
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record(["seed", "falls_at_hz", "balances_at_hz", "runs"])?;
    let hz = |x: Option<f64>| x.map_or_else(String::new, |x| x.to_string());
    for c in &cliffs {
        w.write_record([
            c.seed.to_string(),
            hz(c.falls_at_hz),
            hz(c.balances_at_hz),
            c.runs.to_string(),
        ])?;
    }
    Ok(String::from_utf8(w.into_inner()?)?)
}

/// What `ratelab exercise` found, and the report it printed.
#[derive(Clone, Debug)]
pub struct ExerciseOutcome {
    /// Its checks, reconcile sentences and what did not pass.
    pub report: ratelab::exercise::Report,
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
