//! A run whose results are returned in memory rather than printed, for a program that hosts
//! ratelab (the Python package's `ratelab.run`): the contents of the files `ratelab run
//! --out` writes (`metrics.json`, `trace.csv`, `log.txt`), made by the same code from the
//! same [`RunSpec`], so a run asked for this way equals the command line's in every figure.
//! Its trace is held in memory, so a run whose trace would pass [`MAX_HELD_TRACE_VALUES`]
//! is refused before it starts ([`TraceTooLarge`]).

use crate::run_spec::RunSpec;
use crate::start::{StartCheck, StartOptions};
use ratelab_core::limits::MAX_HELD_TRACE_VALUES;
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::policy::Policy;
use ratelab_runtime::scheduler::{EndReason, StopFlag};
use ratelab_runtime::setting::Speech;
use ratelab_runtime::RunConfig;
use std::path::PathBuf;

/// A run's results, as `ratelab run --out DIR` writes them.
#[derive(Clone, Debug)]
pub struct RunFiles {
    /// `metrics.json`'s text (pretty, the same key order; docs/metrics.md).
    pub metrics_json: String,
    /// `estimator.json`'s text, when the graph has an estimator (its error and lag against
    /// the truth, [`ratelab_core::estimate::EstimateReport`]).
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
/// [`TraceTooLarge`], naming the keep-one-in that fits in `speech`'s words (`trace_every=2`
/// in Python, `--trace-every 2` on the command line).
pub fn check_held_trace(cfg: &RunConfig, every: u64, speech: Speech) -> Result<(), TraceTooLarge> {
    let columns = crate::trace_csv::column_count(&cfg.graph).max(1) as u64;
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
        "{}; keep one step in {fits} or more ({}), or write trace.csv as the run goes with `ratelab run --out DIR`",
        ratelab_core::limits::refusal(what, "MAX_HELD_TRACE_VALUES"),
        speech.value(ratelab_runtime::setting::Setting::TraceEvery, &fits)
    );
    Err(TraceTooLarge {
        values,
        every: fits,
        line,
    })
}

/// One run of `spec`, as `ratelab run --out` makes it ([`RunSpec::start`]), with the brain
/// `brain` in place of `spec.policy`'s when given, until `stop`; `classes` names the
/// graph's Python nodes a caller gives classes for (each must be one). Refusals name
/// settings in `speech`'s words. Nothing is printed but the graph's QoS warnings (stderr):
/// the nodes' lines are kept for [`RunFiles::log`]. With `spec.outputs.out` the files are
/// written as well. The trace's rows are written into memory as the run goes (no step
/// record is kept beside them), within [`MAX_HELD_TRACE_VALUES`].
///
/// # Errors
/// One line: bad settings ([`RunSpec::config`]), a class for a node that is not one of the
/// graph's Python nodes, a trace past [`MAX_HELD_TRACE_VALUES`] ([`TraceTooLarge`], before
/// the run), a brain or graph file that cannot be read, an output that exists without
/// `force`, a recording that could not be finished.
pub fn run(
    spec: &RunSpec,
    brain: Option<Box<dyn Policy>>,
    classes: &[String],
    speech: Speech,
    stop: StopFlag,
) -> anyhow::Result<RunFiles> {
    let classes = classes.to_vec();
    let every = spec.outputs.trace_every;
    let check: StartCheck = Box::new(move |cfg: &RunConfig| -> anyhow::Result<()> {
        check_classes(&cfg.graph, &classes, speech)?;
        // The trace is returned in memory: one that would not fit is refused now, not when
        // the process runs out of memory.
        check_held_trace(cfg, every, speech)?;
        Ok(())
    });
    let opts = StartOptions {
        brain,
        check: Some(check),
        ..StartOptions::held(speech, stop)
    };
    let mut done = spec.clone().start(opts)?.wait()?;
    if let Some(e) = done.unrecorded.take() {
        return Err(e.into());
    }
    let trace = done.write_files()?.unwrap_or_default();
    let report = &done.report;
    let summary = report.metrics.summary_lines(None);
    // The command line's words for it (`ratelab run` exits 2 with this line).
    let failed = matches!(report.end.reason, EndReason::NodeFailed { .. })
        .then(|| crate::outputs::end_is_an_error(report).err())
        .flatten()
        .map(|e| e.to_string());
    Ok(RunFiles {
        metrics_json: serde_json::to_string_pretty(&report.metrics)? + "\n",
        estimator_json: match &report.metrics.estimate {
            Some(e) => Some(serde_json::to_string_pretty(e)? + "\n"),
            None => None,
        },
        trace_csv: String::from_utf8(trace)?,
        log: std::mem::take(&mut done.log),
        summary,
        failed,
        recording: done.recording.as_ref().map(|r| r.path().to_path_buf()),
        wall_s: done.report.wall.as_secs_f64(),
    })
}

/// Each of `classes` must name one of `graph`'s Python nodes (a class given for another
/// name would be silently unused).
///
/// # Errors
/// One line naming the first that does not, and the graph's Python nodes.
fn check_classes(graph: &GraphSpec, classes: &[String], speech: Speech) -> anyhow::Result<()> {
    let python: Vec<&str> = (graph.nodes.iter())
        .filter(|n| n.python.is_some())
        .map(|n| n.name.as_str())
        .collect();
    let Some(stray) = classes.iter().find(|c| !python.contains(&c.as_str())) else {
        return Ok(());
    };
    let given = match speech {
        Speech::Flags => format!("a class for node '{stray}'"),
        Speech::Keywords => format!("nodes[{stray:?}]"),
    };
    let what = if graph.node_id(stray).is_some() {
        format!(
            "node '{stray}' of graph '{}' is a built-in node, not a Python one",
            graph.name
        )
    } else {
        format!(
            "graph '{}' has no node '{stray}' (its nodes: {})",
            graph.name,
            graph.node_names().join(", ")
        )
    };
    let python = if python.is_empty() {
        "it has no Python node (graphs/cartpole-python.toml has one: policy)".to_string()
    } else {
        format!("its Python nodes: {}", python.join(", "))
    };
    anyhow::bail!("{given}: {what}; {python}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::Nanos;

    /// The chapter's graph for `secs` s of run time.
    fn chapter(secs: u64) -> RunConfig {
        RunConfig {
            duration: Nanos(secs * Nanos::SECOND.0),
            ..RunConfig::default()
        }
    }

    #[test]
    fn a_day_of_the_chapter_s_trace_is_held_and_two_are_refused_naming_what_fits() {
        assert_eq!(
            crate::trace_csv::column_count(&RunConfig::default().graph),
            12
        );
        // Steps at 0, 20 ms, …, 10 s (501), and the last counted again: an upper bound.
        assert_eq!(held_rows(&chapter(10), 1), 502);
        assert_eq!(held_rows(&chapter(10), 10), 52);
        let check = |secs, every| check_held_trace(&chapter(secs), every, Speech::Keywords);
        check(86_400, 1).unwrap();
        let e = check(2 * 86_400, 1).unwrap_err();
        assert_eq!(e.every, 2, "{e}");
        let line = e.to_string();
        assert!(
            line.contains("(ratelab::limits::MAX_HELD_TRACE_VALUES); keep one step in 2 or more (trace_every=2), or write"),
            "{line}"
        );
        assert!(
            !line.contains('\n') && !line.contains("--trace-every"),
            "{line}"
        );
        let flags = check_held_trace(&chapter(2 * 86_400), 1, Speech::Flags).unwrap_err();
        assert!(flags.to_string().contains("(--trace-every 2)"), "{flags}");
        check(2 * 86_400, e.every).unwrap();
        // Ten years (the longest run): refused at once, naming the least that fits.
        let e = check(315_360_000, 1).unwrap_err();
        assert_eq!(e.every, 2820, "{e}");
        check(315_360_000, e.every).unwrap();
        assert!(check(315_360_000, e.every - 1).is_err());
    }
}
