//! One run, end to end: settings + brain → plant, graph, executor → [`RunReport`]. The run
//! core holds the graph under either clock ([`ratelab_runtime::runcore`]): it steps it instant by
//! instant under the virtual clock, and hands it to the real-clock executor's threads under
//! the real clock ([`ratelab_runtime::runcore::RunCore::run_real`]).

pub use ratelab_runtime::command::{Command, TimedCommand};
pub use ratelab_runtime::runcore::{build_graph, virtual_scheduler};
pub use ratelab_runtime::summary::{summarize, summarize_state, ActuatorSummary, GraphState};

use crate::observer::{Observers, RunObserver};
use ratelab_core::metrics::Metrics;
use ratelab_core::runlog::StepRecord;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::graph::lock;
use ratelab_runtime::policy::Policy;
use ratelab_runtime::runcore::drive::{ClockOut, Pacer};
use ratelab_runtime::runcore::{CoreOptions, RunCore};
use ratelab_runtime::scheduler::{RealOptions, RunEnd, StopFlag};
use std::time::{Duration, Instant};

/// Why a run could not start.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Its settings, plant or graph could not be built ([`ratelab_runtime::runcore::RunError`]).
    #[error(transparent)]
    Build(#[from] ratelab_runtime::runcore::RunError),
    /// The graph could not be offered to ROS 2 (`--ros2`).
    #[error(transparent)]
    Ros2(#[from] ratelab_ros2::Ros2Error),
}

/// Extras for a run.
#[derive(Default)]
pub struct RunOptions {
    /// Told about the run as it goes, in this order ([`RunObserver`]: every step, and under
    /// the real clock every node tick, under the virtual clock every tick as its executor ran
    /// it when executors or compute times apply). A step observer of the run core's
    /// ([`ratelab_runtime::graph::StepObserver`]) is one, told of steps only.
    pub observers: Vec<Box<dyn RunObserver>>,
    /// Stops the run from outside (Ctrl-C).
    pub stop: StopFlag,
    /// Keep every step record in the report (default true via [`RunOptions::new`]).
    pub keep_trace: bool,
    /// Keep only every this many steps' records, and the last (`--trace-every`; 0 and 1:
    /// every one).
    pub trace_every: u64,
    /// Commands to apply at run times (sorted by `at_ns`; virtual clock).
    pub commands: Vec<TimedCommand>,
    /// Commands applied once the run has ended, before its summary (virtual clock): what a
    /// lab's user changed after the run's last instant, paused, before a restart or quit.
    /// They set the settings the run ended with (the summary's end rates), as they did in
    /// the live run, and no tick (`replay`). Each at the time it was logged (an injected
    /// fault is booked from it, [`ratelab_runtime::command::Command::apply`]).
    pub after_end: Vec<TimedCommand>,
    /// Offer the graph to ROS 2 while it runs ([`ratelab_ros2`]). Under the virtual clock the
    /// run then keeps pace with the wall clock (one second of run time per second), so
    /// that ROS 2's tools see the graph's rates; its results are unchanged. The session
    /// opens once the graph is built (a graph that cannot be built waits for no router).
    pub ros2: Option<ratelab_ros2::Ros2Options>,
}

impl RunOptions {
    /// Keep the trace, no observers, no commands.
    pub fn new() -> Self {
        Self {
            keep_trace: true,
            ..Self::default()
        }
    }
}

/// What a finished run produced.
pub struct RunReport {
    /// The summary (`metrics.json`).
    pub metrics: Metrics,
    /// One record per actuator tick.
    pub trace: Vec<StepRecord>,
    /// How it ended.
    pub end: RunEnd,
    /// Wall time the run took.
    pub wall: Duration,
    /// What was offered to ROS 2 (with [`RunOptions::ros2`]).
    pub ros2: Option<ratelab_ros2::BridgeReport>,
}

/// The real-clock executor's options for `cfg`: its spin margin, phase offsets, real-time
/// priority and execution plan (measuring when the graph has executors or compute times);
/// no tick hook, no pause, time zero when the run starts.
pub fn real_options(cfg: &RunConfig) -> RealOptions {
    RealOptions {
        spin_margin: cfg.spin_margin,
        phase_offsets: cfg.first_deadlines(),
        rt_priority: cfg.rt_priority,
        plan: Some(cfg.graph.execution_plan()),
        track: cfg.graph.has_executors_or_compute(),
        ..RealOptions::default()
    }
}

/// Run the graph once under `cfg.clock` and summarize it. The graph must have no external
/// node without ROS 2, and with [`RunOptions::ros2`] it must be offerable
/// (`ratelab_ros2::bridge::check`): both checked first.
///
/// # Errors
/// [`RunError`] when the run cannot start. A node that panics (under either clock) ends
/// the run with [`ratelab_runtime::scheduler::EndReason::NodeFailed`] instead: the report has what
/// was measured up to then.
pub fn run(
    cfg: &RunConfig,
    brain: Box<dyn Policy>,
    mut opts: RunOptions,
) -> Result<RunReport, RunError> {
    match &opts.ros2 {
        None => ratelab_ros2::external::check_offered(&cfg.graph),
        Some(o) => ratelab_ros2::bridge::check(&cfg.graph, o),
    }
    .map_err(ratelab_ros2::Ros2Error::Usage)?;
    let observers = Observers::new(std::mem::take(&mut opts.observers));
    run_end_to_end(cfg, brain, opts, &observers, Checked::No)
}

/// [`run`] for a run [`crate::start`] made: `cfg` validated by `RunSpec::config` (its last
/// rule) and its ROS 2 checked by [`crate::outputs::ros2_options`], so neither is checked
/// again; `observers` (shared with the text log's sink) in place of `opts.observers`, which
/// is not read.
///
/// # Errors
/// As [`run`]'s, but for the checks.
pub(crate) fn run_checked(
    cfg: &RunConfig,
    brain: Box<dyn Policy>,
    opts: RunOptions,
    observers: &Observers,
) -> Result<RunReport, RunError> {
    run_end_to_end(cfg, brain, opts, observers, Checked::Yes)
}

/// Whether a run's settings were validated and its ROS 2 checked already.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Checked {
    Yes,
    No,
}

/// The run core for `cfg` with `brain`, telling `observers`, keeping the trace or not, with
/// commands at run times under the virtual clock; built without validating `cfg` again when
/// it was (`checked`).
fn build_core(
    cfg: &RunConfig,
    brain: Box<dyn Policy>,
    opts: &mut RunOptions,
    observers: &Observers,
    checked: Checked,
) -> Result<RunCore, RunError> {
    let mut core_opts = CoreOptions {
        keep_trace: opts.keep_trace,
        observers: observers.step_observers(),
        // Commands at run times are the virtual clock's (`replay`).
        commands: if cfg.clock == ClockKind::Virtual {
            std::mem::take(&mut opts.commands)
        } else {
            Vec::new()
        },
        on_span: observers.span_hook(),
        remake_brain: None,
        remake_observers: None,
        history_every: None,
    };
    Ok(match checked {
        Checked::No => RunCore::new(cfg, brain, core_opts)?,
        Checked::Yes => {
            // `cfg` was validated by `RunSpec::config`, last: not again.
            let steps = std::mem::take(&mut core_opts.observers);
            let graph = ratelab_runtime::runcore::build_validated_graph(
                cfg,
                ratelab_runtime::policy::BrainSlot::new(brain),
                core_opts.keep_trace,
                steps,
            )?;
            RunCore::with_graph(cfg, graph, core_opts)
        }
    })
}

/// Offer the run core's graph to ROS 2 (said on stderr): its session opened
/// ([`ratelab_ros2::session::open`], after the graph is built, as a ROS 2 node opens its
/// context), the bridge started; returns the bridge, and the session to close when the run
/// ends. A bridge that cannot start closes the session.
fn offer_to_ros2(
    cfg: &RunConfig,
    core: &RunCore,
    options: Option<ratelab_ros2::Ros2Options>,
    stop: &StopFlag,
) -> Result<Option<(ratelab_ros2::Bridge, ratelab_ros2::session::Ros2Session)>, RunError> {
    let Some(options) = options else {
        return Ok(None);
    };
    let env = ratelab_ros2::session::SessionEnv::from_process();
    let session = ratelab_ros2::session::open(&env, stop)?;
    let whole = ratelab_ros2::bridge::Offer::whole(core.handles());
    match ratelab_ros2::Bridge::start(&session, &whole, &options, cfg.clock, stop) {
        Ok(b) => {
            eprintln!("[ratelab] {}", b.describe());
            Ok(Some((b, session)))
        }
        Err(e) => {
            session.close();
            Err(e.into())
        }
    }
}

/// One run, end to end, once its checks are done (`checked`) or skipped: the run core
/// built, offered to ROS 2, run under `cfg.clock`, summarized; `observers` told of it all
/// and of its end.
fn run_end_to_end(
    cfg: &RunConfig,
    brain: Box<dyn Policy>,
    mut opts: RunOptions,
    observers: &Observers,
    checked: Checked,
) -> Result<RunReport, RunError> {
    let virtual_clock = cfg.clock == ClockKind::Virtual;
    let mut core = build_core(cfg, brain, &mut opts, observers, checked)?;
    let handles = core.handles().clone();
    lock(&handles.log).trace_every = opts.trace_every;
    let ros2 = offer_to_ros2(cfg, &core, opts.ros2.take(), &opts.stop)?;
    let bridge = ros2.as_ref().map(|(b, _)| b);
    let start = Instant::now();
    let (end, ticks, timing, exec) = if virtual_clock {
        // Offered to ROS 2, the run keeps pace with the wall clock and tells /clock;
        // otherwise it runs unpaced.
        let mut pacer = Pacer::new(Nanos::ZERO, bridge.map(|_| 1.0));
        let clock = bridge.map(|b| b as &dyn ClockOut);
        let end = core.run_to_end_with(&mut pacer, &opts.stop, clock);
        for c in &opts.after_end {
            // One refused here was refused in the live run too, when made: never logged.
            let _ = core.apply_after_end(c);
        }
        let exec = core.scheduler().figures(end.at);
        (end, core.scheduler().ticks().to_vec(), None, exec)
    } else {
        let real = RealOptions {
            on_tick: observers.tick_hook(),
            ..real_options(cfg)
        };
        let r = core.run_real(None, &opts.stop, &real);
        let ticks = r.timing.iter().map(|t| t.ticks).collect();
        (r.end, ticks, Some(r.timing), r.exec)
    };
    let wall = start.elapsed();
    let ros2 = ros2.map(|(bridge, link)| {
        let report = bridge.finish();
        link.close();
        report
    });
    let metrics = summarize(cfg, &handles, &end, &ticks, timing, exec);
    let trace = kept_trace(&handles);
    observers.end(&metrics, &end);
    Ok(RunReport {
        metrics,
        trace,
        end,
        wall,
        ros2,
    })
}

/// The step records the run log kept: a thinned trace ends with the run's last step all the
/// same.
fn kept_trace(handles: &ratelab_runtime::graph::GraphHandles) -> Vec<StepRecord> {
    let mut log = lock(&handles.log);
    let mut trace = std::mem::take(&mut log.trace);
    if let Some(last) = log.last.as_ref().filter(|_| log.keep_trace) {
        if trace.last().is_none_or(|r| r.step != last.step) {
            trace.push(last.clone());
        }
    }
    trace
}
