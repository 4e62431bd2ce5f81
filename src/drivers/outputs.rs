//! Where a run's results go besides its report, and how they are opened, written and
//! judged, for every front end: the files of `--out` (`metrics.json`, `trace.csv`,
//! `log.txt`, `estimator.json`), the rerun recording, the ROS 2 offer and its bag, the text
//! log the nodes write; and a run that reached its summary but failed, as an error.
//!
//! [`Outputs`] is the data (a field of [`crate::run_spec::RunSpec`]); each is checked and
//! opened here ([`ros2_options`], [`open_ros2`], [`check_out`], [`open_recording`]), and
//! finished here ([`finish_recording`], [`write_outputs`]). `RunSpec::start`
//! ([`crate::start`]) opens them for a run and attaches them to it.

use crate::run::RunReport;
use crate::trace_csv::TraceFile;
use anyhow::Context;
use ratelab_recording::{
    check_output_path, default_path, RecordOptions, Recording, RecordingError,
};
use ratelab_runtime::graph::GraphSpec;
use ratelab_runtime::scheduler::{EndReason, StopFlag};
use ratelab_runtime::setting::{Setting, Speech};
use ratelab_runtime::RunConfig;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Where a run's results go besides its report: the files of `--out`, the recording, ROS 2.
#[derive(Clone, Debug, PartialEq)]
pub struct Outputs {
    /// The folder of `metrics.json`, `trace.csv`, `log.txt` (and `estimator.json` with an
    /// estimator in the graph).
    pub out: Option<PathBuf>,
    /// `trace.csv` keeps one actuator step in this many (steps 1, 1 + N, …, and the last);
    /// at least 1.
    pub trace_every: u64,
    /// A rerun recording: `Some(None)` at its default path under `recordings/`.
    pub record: Option<Option<PathBuf>>,
    /// Stream live to a rerun viewer as well (implies a recording).
    pub spawn: bool,
    /// Record only this span of run time.
    pub record_window: Option<ratelab_recording::RecordWindow>,
    /// Replace existing output files (never links or non-regular files).
    pub force: bool,
    /// Offer the graph to ROS 2 on this domain ([`Outputs::ros2_domain`]).
    pub ros2: Option<Ros2Domain>,
    /// With ROS 2: also write a rosbag2 bag (MCAP) in this folder.
    pub bag: Option<PathBuf>,
}

impl Default for Outputs {
    /// Nothing but the report: no files, no recording, no ROS 2; every step kept.
    fn default() -> Self {
        Self {
            out: None,
            trace_every: 1,
            record: None,
            spawn: false,
            record_window: None,
            force: false,
            ros2: None,
            bag: None,
        }
    }
}

/// Which ROS 2 domain a run is offered on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ros2Domain {
    /// This one (0–232).
    Given(u32),
    /// `ROS_DOMAIN_ID`'s, else 0, as every ROS 2 node picks its domain.
    FromEnvironment,
}

impl Outputs {
    /// The ROS 2 domain the run is offered on: `None` without ROS 2; the one given; else
    /// `ROS_DOMAIN_ID`'s, else 0 (rcl's rule).
    ///
    /// # Errors
    /// `ROS_DOMAIN_ID` is set to something that is not a domain.
    pub fn ros2_domain(&self) -> Result<Option<u32>, String> {
        match self.ros2 {
            None => Ok(None),
            Some(Ros2Domain::Given(d)) => Ok(Some(d)),
            Some(Ros2Domain::FromEnvironment) => match std::env::var("ROS_DOMAIN_ID") {
                Ok(v) if !v.trim().is_empty() => ratelab_ros2::names::parse_domain(&v)
                    .map(Some)
                    .map_err(|e| format!("ROS_DOMAIN_ID: {e}")),
                _ => Ok(Some(0)),
            },
        }
    }
}

/// `--ros2` as `a` gives it (the domain from the flag or `ROS_DOMAIN_ID`, the bag), checked
/// against `graph` before anything opens: ROS 2's names, `/clock`, the bag's folder. Without
/// `--ros2` the graph must have no external node (nothing else could fill it). Used by
/// `run`, the lab and a launch.
///
/// # Errors
/// The first problem, in one line (exit 2).
pub fn ros2_options(
    a: &Outputs,
    graph: &GraphSpec,
) -> anyhow::Result<Option<ratelab_ros2::Ros2Options>> {
    let opts =
        a.ros2_domain()
            .map_err(anyhow::Error::msg)?
            .map(|domain| ratelab_ros2::Ros2Options {
                domain,
                bag: a.bag.clone(),
                force: a.force,
            });
    match &opts {
        Some(o) => ratelab_ros2::bridge::check(graph, o),
        None => ratelab_ros2::external::check_offered(graph),
    }
    .map_err(anyhow::Error::msg)?;
    Ok(opts)
}

/// The ROS 2 session, opened as rmw_zenoh's nodes open theirs (with an embedded router when
/// none answers), from the process's `ZENOH_*` variables; `stop` ends a wait for a router.
///
/// # Errors
/// A bad variable or a failed session, in one line.
pub fn open_ros2(stop: &StopFlag) -> anyhow::Result<ratelab_ros2::session::Ros2Session> {
    let env = ratelab_ros2::session::SessionEnv::from_process();
    Ok(ratelab_ros2::session::open(&env, stop)?)
}

/// `--out`'s folder made, and its files checked before the run, not after it (refused when
/// they will not be writable).
///
/// # Errors
/// The folder cannot be made, or a file is there without `--force`.
pub fn check_out(a: &Outputs, graph: &GraphSpec, speech: Speech) -> anyhow::Result<()> {
    if let Some(dir) = &a.out {
        std::fs::create_dir_all(dir).with_context(|| {
            format!(
                "cannot create {} folder {}",
                speech.name(Setting::Out),
                dir.display()
            )
        })?;
        // Refuse before the run, not after it: the outputs will not be writable.
        let estimator = graph.estimate_topic().map(|_| ESTIMATOR_JSON);
        for name in OUT_FILES.into_iter().chain(estimator) {
            ratelab_core::output::check_writable(&dir.join(name), a.force)?;
        }
    }
    Ok(())
}

/// The files `--out` writes in one process, whatever the graph ([`write_outputs`]): each is
/// checked before the run ([`check_out`]) and again before any is written.
const OUT_FILES: [&str; 3] = ["metrics.json", "trace.csv", "log.txt"];

/// With an estimator in the graph, `--out`'s file of its error and lag against the truth
/// ([`ratelab_core::estimate::EstimateReport`]; not in `metrics.json`, whose bytes the reference
/// runs fix).
pub const ESTIMATOR_JSON: &str = "estimator.json";

/// The lines nodes wrote, as `log.txt` holds them (one per line, a newline after each).
pub fn log_text(kept: &Mutex<Vec<String>>) -> String {
    let log = kept.lock().unwrap_or_else(|e| e.into_inner()).join("\n");
    if log.is_empty() {
        log
    } else {
        log + "\n"
    }
}

/// What a run kept of the lines its nodes wrote (`log.txt`'s, the first [`MAX_LOG_LINES`]).
pub type KeptLog = Arc<Mutex<Vec<String>>>;

/// Finish the run's recording: `Some(error)` when it could not be finished (a full disk),
/// which fails the run after its summary and other files. With `--spawn` a live viewer
/// that could not start or went away costs neither the file nor the summary.
pub fn finish_recording(
    a: &Outputs,
    recording: Option<&Recording>,
    report: &RunReport,
) -> Option<ratelab_recording::RecordingError> {
    match recording?.finish(&report.metrics, &report.end) {
        Err(e) if a.spawn => {
            eprintln!("[ratelab] warning: live viewer: {e} (the file is written)");
            None
        }
        Err(e) => Some(e),
        Ok(()) => None,
    }
}

/// A run that reached its summary and files but did not succeed is, after them, an error
/// (exit 2, one line), in every command and process layout (`run`, `launch` in one process
/// or across processes, under either clock): a node that failed (a panic, a Python
/// exception, `sys.exit`), whatever the pole did meanwhile, or [`no_success_is_an_error`]'s
/// cases.
///
/// # Errors
/// One line naming the failed node and its error's first line, or `no_success`'s.
pub fn end_is_an_error(report: &RunReport) -> anyhow::Result<()> {
    if let EndReason::NodeFailed { node, message } = &report.end.reason {
        anyhow::bail!(
            "node '{node}' failed at t={:.2}s: {}",
            report.end.at.as_secs_f64(),
            message.lines().next().unwrap_or("panic")
        );
    }
    no_success_is_an_error(&report.metrics)
}

/// The most lines of the run's text log `--out` keeps in `log.txt` (each is on stderr as
/// well).
pub const MAX_LOG_LINES: usize = 100_000;

/// A run that reached its summary but is no success (`Metrics::no_success`: a deadline
/// watchdog's stop, as a ROS 2 node's deadline-missed handler may stop the system, or an
/// actuator killed within the run) is, after its summary and files, an error (exit 2),
/// never a success that a script could take for a balanced run.
///
/// # Errors
/// One line, `Metrics::no_success`'s.
pub fn no_success_is_an_error(metrics: &ratelab_core::metrics::Metrics) -> anyhow::Result<()> {
    match metrics.no_success() {
        Some(why) => anyhow::bail!("{why}"),
        None => Ok(()),
    }
}

/// The `--record`/`--spawn` recording, checked and opened before the run starts.
pub fn open_recording(
    a: &Outputs,
    cfg: &RunConfig,
    policy: &str,
    speech: Speech,
) -> anyhow::Result<Option<Recording>> {
    let refused = |cause: RecordingError| RecordRefused {
        line: cause.said(speech),
        cause,
    };
    if a.record.is_none() && !a.spawn {
        return Ok(None);
    }
    let path: PathBuf = match a.record.clone().flatten() {
        Some(p) => p,
        None => default_path(Path::new("recordings"), cfg),
    };
    check_output_path(&path, a.force).map_err(refused)?;
    let (recording, notice) = Recording::create_with(
        &path,
        cfg,
        policy,
        &RecordOptions {
            spawn: a.spawn,
            window: a.record_window,
            // Said in its settings: a run offered to ROS 2, and bagged (checked already by
            // `ros2_options`, which a bad `ROS_DOMAIN_ID` fails first).
            ros2_domain: a.ros2_domain().ok().flatten(),
            bag: a.bag.clone().filter(|_| a.ros2.is_some()),
        },
        a.force,
    )
    .map_err(refused)?;
    if let Some(n) = notice {
        eprintln!("[ratelab] {n}");
    }
    Ok(Some(recording))
}

/// A recording that cannot be opened ([`open_recording`]): its line in the front end's words
/// (`--record …` or `record: …`, [`RecordingError::said`]), and its cause, which says what
/// kind of refusal it is (a Python front end raises `FileExistsError` for
/// [`RecordingError::Exists`]).
#[derive(Debug)]
pub struct RecordRefused {
    /// The refusal, in the front end's words.
    pub line: String,
    /// What refused it.
    pub cause: RecordingError,
}

impl std::fmt::Display for RecordRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.line)
    }
}

// No `source`: the line already says the cause, and a chain would say it twice.
impl std::error::Error for RecordRefused {}

/// `trace.csv` as [`write_outputs`] puts it in place.
pub enum TraceCsv<'a> {
    /// Written to a temporary file beside its name as the run went (`ratelab run --out`):
    /// moved into place.
    Streamed(TraceFile),
    /// Held whole (`ratelab.run`, which returns it): written.
    Held(&'a [u8]),
}

/// `metrics.json` (pretty, stable key order), `trace.csv` (one row per actuator tick kept:
/// `trace`) and `log.txt` (the lines nodes wrote, `log`), each through [`ratelab_core::output`]
/// (never over an existing file unless `force`).
pub fn write_outputs(
    dir: &Path,
    report: &RunReport,
    log: &str,
    force: bool,
    trace: TraceCsv<'_>,
) -> anyhow::Result<()> {
    // Every name is checked before any is written, so a refusal writes nothing.
    let paths = OUT_FILES.map(|name| dir.join(name));
    for path in &paths {
        ratelab_core::output::check_target(path, force)?;
    }
    let [metrics, trace_csv, log_txt] = paths;
    let estimator = report
        .metrics
        .estimate
        .as_ref()
        .map(|e| (dir.join(ESTIMATOR_JSON), e));
    if let Some((path, _)) = &estimator {
        ratelab_core::output::check_target(path, force)?;
    } else if force {
        // Replacing a run's files: another run's estimator figures do not stay beside them.
        match std::fs::remove_file(dir.join(ESTIMATOR_JSON)) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                anyhow::bail!("cannot remove {}: {e}", dir.join(ESTIMATOR_JSON).display())
            }
            _ => {}
        }
    }
    let json = serde_json::to_string_pretty(&report.metrics)? + "\n";
    ratelab_core::output::write_file(&metrics, force, json.as_bytes())?;
    if let Some((path, e)) = &estimator {
        let json = serde_json::to_string_pretty(e)? + "\n";
        ratelab_core::output::write_file(path, force, json.as_bytes())?;
    }
    match trace {
        TraceCsv::Streamed(file) => file.commit()?,
        TraceCsv::Held(bytes) => ratelab_core::output::write_file(&trace_csv, force, bytes)?,
    }
    ratelab_core::output::write_file(&log_txt, force, log.as_bytes())?;
    Ok(())
}
