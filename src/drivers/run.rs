//! One run, end to end: settings + brain → plant, graph, executor → [`RunReport`]. The run
//! core holds the graph under either clock ([`ratelab_runtime::runcore`]): it steps it instant by
//! instant under the virtual clock, and hands it to the real-clock executor's threads under
//! the real clock ([`ratelab_runtime::runcore::RunCore::run_real`]).

pub use ratelab_runtime::command::{Command, TimedCommand};
pub use ratelab_runtime::runcore::{build_graph, virtual_scheduler};
pub use ratelab_runtime::summary::{summarize, summarize_state, ActuatorSummary, GraphState};

use ratelab_core::metrics::Metrics;
use ratelab_core::runlog::StepRecord;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::graph::{lock, StepObserver};
use ratelab_runtime::policy::Policy;
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
    /// Told about every actuator tick.
    pub observers: Vec<Box<dyn StepObserver>>,
    /// Stops the run from outside (Ctrl-C).
    pub stop: StopFlag,
    /// Keep every step record in the report (default true via [`RunOptions::new`]).
    pub keep_trace: bool,
    /// Keep only every this many steps' records, and the last (`--trace-every`; 0 and 1:
    /// every one).
    pub trace_every: u64,
    /// Commands to apply at run times (sorted by `at_ns`; virtual clock).
    pub commands: Vec<TimedCommand>,
    /// Real clock: told about every node tick.
    pub on_node_tick: Option<ratelab_runtime::scheduler::TickHook>,
    /// Virtual clock, when executors or compute times apply: told about every tick as its
    /// executor ran it (release, start, end).
    pub on_span: Option<ratelab_core::executor::SpanHook>,
    /// Offer the graph to ROS 2 while it runs ([`ratelab_ros2`]). Under the virtual clock the
    /// run then keeps pace with the wall clock (one second of run time per second), so
    /// that ROS 2's tools see the graph's rates; its results are unchanged.
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

/// Run the graph once under `cfg.clock` and summarize it.
///
/// # Errors
/// [`RunError`] when the run cannot start. A node that panics (under either clock) ends
/// the run with [`ratelab_runtime::scheduler::EndReason::NodeFailed`] instead: the report has what
/// was measured up to then.
pub fn run(
    cfg: &RunConfig,
    brain: Box<dyn Policy>,
    opts: RunOptions,
) -> Result<RunReport, RunError> {
    if opts.ros2.is_none() {
        ratelab_ros2::external::check_offered(&cfg.graph)
            .map_err(ratelab_ros2::Ros2Error::Usage)?;
    }
    let virtual_clock = cfg.clock == ClockKind::Virtual;
    let mut core = ratelab_runtime::runcore::RunCore::new(
        cfg,
        brain,
        ratelab_runtime::runcore::CoreOptions {
            keep_trace: opts.keep_trace,
            observers: opts.observers,
            // Commands at run times are the virtual clock's (`replay`).
            commands: if virtual_clock {
                opts.commands.clone()
            } else {
                Vec::new()
            },
            on_span: opts.on_span.clone(),
            remake_brain: None,
            remake_observers: None,
            history_every: None,
        },
    )?;
    let handles = core.handles().clone();
    lock(&handles.log).trace_every = opts.trace_every;
    let link = match &opts.ros2 {
        Some(o) => {
            // What needs no network is refused before a session (or a router) opens.
            ratelab_ros2::bridge::check(&cfg.graph, o).map_err(ratelab_ros2::Ros2Error::Usage)?;
            let env = ratelab_ros2::session::SessionEnv::from_process();
            Some(ratelab_ros2::session::open(&env, &opts.stop)?)
        }
        None => None,
    };
    let bridge = match (&opts.ros2, &link) {
        (Some(o), Some(link)) => {
            let offer = ratelab_ros2::bridge::Offer::whole(&handles);
            let b = ratelab_ros2::Bridge::start(link, &offer, o, cfg.clock, &opts.stop)?;
            eprintln!("[ratelab] {}", b.describe());
            Some(b)
        }
        _ => None,
    };
    let start = Instant::now();
    let (end, ticks, timing, exec) = if virtual_clock {
        let end = core.run_to_end_with(&opts.stop, |t| {
            if let Some(b) = &bridge {
                // Keep pace with the wall clock, then tell ROS 2 the time.
                let due = start + Duration::from_nanos(t.0);
                if let Some(wait) = due.checked_duration_since(Instant::now()) {
                    std::thread::sleep(wait);
                }
                b.clock(t);
            }
        });
        let exec = core.scheduler().figures(end.at);
        (end, core.scheduler().ticks().to_vec(), None, exec)
    } else {
        let real = RealOptions {
            on_tick: opts.on_node_tick.clone(),
            ..real_options(cfg)
        };
        let r = core.run_real(None, &opts.stop, &real);
        let ticks = r.timing.iter().map(|t| t.ticks).collect();
        (r.end, ticks, Some(r.timing), r.exec)
    };
    let wall = start.elapsed();
    let ros2 = bridge.map(ratelab_ros2::Bridge::finish);
    if let Some(link) = link {
        link.close();
    }
    let metrics = summarize(cfg, &handles, &end, &ticks, timing, exec);
    let trace = {
        let mut log = lock(&handles.log);
        let mut trace = std::mem::take(&mut log.trace);
        // A thinned trace ends with the run's last step all the same.
        if let Some(last) = log.last.as_ref().filter(|_| log.keep_trace) {
            if trace.last().is_none_or(|r| r.step != last.step) {
                trace.push(last.clone());
            }
        }
        trace
    };
    Ok(RunReport {
        metrics,
        trace,
        end,
        wall,
        ros2,
    })
}
