//! ratelab's run for a program that hosts the command line as a library (the Python package,
//! `src/py`): `ratelab run`'s flags in, the contents of the files `ratelab run --out` writes
//! out (`metrics.json`, `trace.csv`, `log.txt`), made by the same code, so a run asked for
//! this way equals the command line's in every figure. Its trace is returned in memory, so a
//! run whose trace would pass [`MAX_HELD_TRACE_VALUES`] is refused before it starts
//! ([`TraceTooLarge`]).

use crate::cli::{Cli, Command};
use crate::headless;
use crate::trace::TraceStream;
use ratelab::limits::MAX_HELD_TRACE_VALUES;
use ratelab::policy::Policy;
use ratelab::scheduler::{EndReason, StopFlag};
use ratelab::RunConfig;
use std::path::PathBuf;

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

/// A run's results, as `ratelab run --out DIR` writes them.
#[derive(Clone, Debug)]
pub struct RunFiles {
    /// `metrics.json`'s text (pretty, the same key order; docs/metrics.md).
    pub metrics_json: String,
    /// `estimator.json`'s text, when the graph has an estimator (its error and lag against
    /// the truth, [`ratelab::estimate::EstimateReport`]).
    pub estimator_json: Option<String>,
    /// `trace.csv`'s text: a header, then one row per actuator tick.
    pub trace_csv: String,
    /// `log.txt`'s text: every line the nodes wrote, stamped `[t=1.234 s node]`.
    pub log: String,
    /// The summary `ratelab run` prints, one line each, without its `[ratelab]` prefix and
    /// the wall time.
    pub summary: Vec<String>,
    /// Why the run failed (a node failed: the line `ratelab run` ends with), when it did;
    /// the figures above are still those up to the failure.
    pub failed: Option<String>,
    /// The recording written (`--record`), when one was.
    pub recording: Option<PathBuf>,
    /// The wall time the run itself took (what `ratelab run`'s summary gives as `wall`), s.
    pub wall_s: f64,
}

/// A run refused before it started: the trace [`run`] returns in memory would hold more than
/// [`MAX_HELD_TRACE_VALUES`] values (rows × columns). `ratelab.TraceTooLarge` in Python, a
/// `MemoryError`.
#[derive(Debug)]
pub struct TraceTooLarge {
    /// The values the trace would hold, at most.
    pub values: u64,
    /// The smallest `--trace-every` (one step in this many kept) whose trace fits.
    pub every: u64,
    line: String,
}

impl std::fmt::Display for TraceTooLarge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.line)
    }
}

impl std::error::Error for TraceTooLarge {}

/// The actuator steps of a run of `cfg`, at most: one every period (the plant's 20 ms) from
/// its first tick, at or after 0, to the duration.
fn steps_at_most(cfg: &RunConfig) -> u64 {
    let period = (1e9 / cfg.graph.actuator_hz()).round().max(1.0) as u64;
    cfg.duration.0 / period + 1
}

/// The rows of a run of `cfg`'s trace that keeps one step in `every` (0 and 1: each), at
/// most: steps 1, 1 + every, …, and the last.
fn held_rows(cfg: &RunConfig, every: u64) -> u64 {
    steps_at_most(cfg).div_ceil(every.max(1)) + 1
}

/// Refuse, before it starts, a run of `cfg` keeping one step in `every` whose trace, held in
/// memory, would pass [`MAX_HELD_TRACE_VALUES`] values.
///
/// # Errors
/// [`TraceTooLarge`], naming the `--trace-every` that fits.
pub fn check_held_trace(cfg: &RunConfig, every: u64) -> Result<(), TraceTooLarge> {
    let columns = crate::trace::column_count(&cfg.graph).max(1) as u64;
    let rows = held_rows(cfg, every);
    let values = rows.saturating_mul(columns);
    if values <= MAX_HELD_TRACE_VALUES {
        return Ok(());
    }
    // Rows that fit, less the last step's; one step in `fits` keeps within them.
    let room = (MAX_HELD_TRACE_VALUES / columns).saturating_sub(1).max(1);
    let fits = steps_at_most(cfg).div_ceil(room);
    let what = format!(
        "a run of {} s returns a trace of {rows} rows × {columns} columns ({values} values), more than ratelab.run holds in memory: at most {MAX_HELD_TRACE_VALUES} values",
        cfg.duration.as_secs_f64()
    );
    let line = format!(
        "{}; keep one step in {fits} or more (trace_every={fits}, --trace-every {fits}), or write trace.csv as the run goes with `ratelab run --out DIR`",
        ratelab::limits::refusal(what, "MAX_HELD_TRACE_VALUES")
    );
    Err(TraceTooLarge {
        values,
        every: fits,
        line,
    })
}

/// Run `ratelab run` with the flags `flags` (without `ratelab run`: `["--control-hz",
/// "5"]`), the brain `brain` in place of `--policy`'s when given, until `stop`. Nothing is
/// printed: the nodes' lines are kept for [`RunFiles::log`]. With `--out` the files are
/// written as well. The trace's rows are written into memory as the run goes (no step
/// record is kept beside them), within [`MAX_HELD_TRACE_VALUES`].
///
/// # Errors
/// One line, as the command line would print it: bad flags (clap's rule), bad settings, a
/// trace past [`MAX_HELD_TRACE_VALUES`] ([`TraceTooLarge`], before the run), a brain or
/// graph file that cannot be read, an output that exists without `--force`, a recording
/// that could not be finished.
pub fn run(
    flags: &[String],
    brain: Option<Box<dyn Policy>>,
    stop: StopFlag,
) -> anyhow::Result<RunFiles> {
    let Command::Run(a) = parse("run", flags)? else {
        anyhow::bail!("not a run");
    };
    let cfg = headless::config_from_args(&a)?;
    // The trace is returned in memory: one that would not fit is refused now, not when the
    // process runs out of memory.
    check_held_trace(&cfg, a.trace_every)?;
    let brain = match brain {
        Some(b) => b,
        None => ratelab::checkpoint::load_policy(&a.policy)?,
    };
    headless::check_out(&a, &cfg.graph)?;
    let trace = TraceStream::new(Vec::new(), &cfg.graph, a.trace_every)?;
    let (report, kept, recording) =
        headless::execute(&a, &cfg, brain, stop, vec![trace.observer()], false)?;
    if let Some(e) = headless::finish_recording(&a, recording.as_ref(), &report) {
        return Err(e.into());
    }
    let trace = trace.finish()?;
    let log = headless::log_text(&kept);
    if let Some(dir) = &a.out {
        headless::write_outputs(
            dir,
            &report,
            &log,
            a.force,
            headless::TraceCsv::Held(&trace),
        )?;
    }
    let summary = report.metrics.summary_lines(None);
    // The command line's words for it (`ratelab run` exits 2 with this line).
    let failed = matches!(report.end.reason, EndReason::NodeFailed { .. })
        .then(|| headless::end_is_an_error(&report).err())
        .flatten()
        .map(|e| e.to_string());
    Ok(RunFiles {
        metrics_json: serde_json::to_string_pretty(&report.metrics)? + "\n",
        estimator_json: match &report.metrics.estimate {
            Some(e) => Some(serde_json::to_string_pretty(e)? + "\n"),
            None => None,
        },
        trace_csv: String::from_utf8(trace)?,
        log,
        summary,
        failed,
        recording: recording.map(|r| r.path().to_path_buf()),
        wall_s: report.wall.as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab::Nanos;

    /// The chapter's graph for `secs` s of run time.
    fn chapter(secs: u64) -> RunConfig {
        RunConfig {
            duration: Nanos(secs * Nanos::SECOND.0),
            ..RunConfig::default()
        }
    }

    #[test]
    fn a_day_of_the_chapter_s_trace_is_held_and_two_are_refused_naming_what_fits() {
        assert_eq!(crate::trace::column_count(&RunConfig::default().graph), 12);
        // Steps at 0, 20 ms, …, 10 s (501), and the last counted again: an upper bound.
        assert_eq!(held_rows(&chapter(10), 1), 502);
        assert_eq!(held_rows(&chapter(10), 10), 52);
        check_held_trace(&chapter(86_400), 1).unwrap();
        let e = check_held_trace(&chapter(2 * 86_400), 1).unwrap_err();
        assert_eq!(e.every, 2, "{e}");
        let line = e.to_string();
        assert!(
            line.contains("(ratelab::limits::MAX_HELD_TRACE_VALUES); keep one step in 2 or more (trace_every=2, --trace-every 2)"),
            "{line}"
        );
        assert!(!line.contains('\n'), "{line}");
        check_held_trace(&chapter(2 * 86_400), e.every).unwrap();
        // Ten years (the longest run): refused at once, naming the least that fits.
        let e = check_held_trace(&chapter(315_360_000), 1).unwrap_err();
        assert_eq!(e.every, 2820, "{e}");
        check_held_trace(&chapter(315_360_000), e.every).unwrap();
        assert!(check_held_trace(&chapter(315_360_000), e.every - 1).is_err());
    }
}
