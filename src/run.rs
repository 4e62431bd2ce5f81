//! One run, end to end: settings + brain → plant, graph, executor → [`RunReport`].

use crate::config::{ClockKind, RunConfig};
use crate::graph::{lock, Graph, GraphHandles, GraphRates, StepObserver};
use crate::metrics::{round_to, Metrics, NodeTiming, StepRecord};
use crate::plant::{CartPole, PlantError};
use crate::policy::{BrainSlot, Policy};
use crate::scheduler::{run_real, RealOptions, RunEnd, StopFlag, VirtualScheduler};
use crate::time::Nanos;
use std::time::{Duration, Instant};

/// A run that could not start.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Bad settings.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The plant could not be built.
    #[error(transparent)]
    Plant(#[from] PlantError),
    /// The graph could not be built.
    #[error(transparent)]
    Graph(#[from] crate::graph::GraphError),
}

/// A change to a running graph. Under the virtual clock each is applied at a virtual
/// instant, so a logged session replays exactly.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "cmd", rename_all = "snake_case")]
pub enum Command {
    /// Set the policy rate, Hz.
    SetControlHz {
        /// New rate.
        hz: f64,
    },
    /// Set the sensor rate, Hz.
    SetSensorHz {
        /// New rate.
        hz: f64,
    },
    /// Set both topics' history depth.
    SetQueueDepth {
        /// New depth (≥ 1).
        depth: usize,
    },
    /// Swap the policy node's brain (`scripted` or a checkpoint path).
    SetPolicy {
        /// The brain spec, as `--policy` takes it.
        spec: String,
    },
}

impl Command {
    /// Apply to a running graph.
    ///
    /// # Errors
    /// A one-line description when the value is invalid or the brain cannot be loaded
    /// (the graph is unchanged).
    pub fn apply(&self, h: &GraphHandles) -> Result<(), String> {
        match self {
            Command::SetControlHz { hz } => h.control_rate.set_hz(*hz).map_err(|e| e.to_string()),
            Command::SetSensorHz { hz } => h.sensor_rate.set_hz(*hz).map_err(|e| e.to_string()),
            Command::SetQueueDepth { depth } => {
                h.set_queue_depth(*depth).map_err(|e| e.to_string())
            }
            Command::SetPolicy { spec } => {
                let brain = crate::checkpoint::load_policy(spec).map_err(|e| e.to_string())?;
                h.brain.swap(brain);
                Ok(())
            }
        }
    }
}

/// A command stamped with the run time at which it takes effect.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TimedCommand {
    /// Run time, ns: applied just before the first tick due at or after it.
    pub at_ns: u64,
    /// The change.
    #[serde(flatten)]
    pub command: Command,
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
    /// Commands to apply at run times (sorted by `at_ns`; virtual clock).
    pub commands: Vec<TimedCommand>,
    /// Real clock: told about every node tick.
    pub on_node_tick: Option<crate::scheduler::TickHook>,
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
}

/// Build the plant (reset to `cfg.seed`) and the graph for `cfg`.
///
/// # Errors
/// [`RunError`] for bad settings or a plant that will not load.
pub fn build_graph(
    cfg: &RunConfig,
    brain: BrainSlot,
    keep_trace: bool,
    observers: Vec<Box<dyn StepObserver>>,
) -> Result<Graph, RunError> {
    cfg.validate()?;
    let mut plant = CartPole::new()?;
    plant.reset(cfg.seed);
    let rates = GraphRates {
        sensor_hz: cfg.sensor_hz,
        control_hz: cfg.control_hz,
        actuator_hz: cfg.actuator_hz,
    };
    Ok(Graph::build(
        plant,
        brain,
        rates,
        cfg.queue_depth,
        keep_trace,
        observers,
    )?)
}

/// Run the graph once under `cfg.clock` and summarize it.
///
/// # Errors
/// [`RunError`] when the run cannot start. A node that panics under the real clock ends
/// the run with [`crate::scheduler::EndReason::NodeFailed`] instead.
pub fn run(
    cfg: &RunConfig,
    brain: Box<dyn Policy>,
    opts: RunOptions,
) -> Result<RunReport, RunError> {
    let brain = BrainSlot::new(brain);
    let Graph { mut nodes, handles } = build_graph(cfg, brain, opts.keep_trace, opts.observers)?;
    let start = Instant::now();
    let (end, timing) = match cfg.clock {
        ClockKind::Virtual => {
            let mut sched = VirtualScheduler::new(&nodes);
            let mut pending = opts.commands.iter().peekable();
            let end = sched.run(&mut nodes, cfg.duration, &opts.stop, &mut |t| {
                while let Some(c) = pending.next_if(|c| c.at_ns <= t.0) {
                    // Commands were validated when logged; a failure here changes nothing.
                    let _ = c.command.apply(&handles);
                }
            });
            (end, None)
        }
        ClockKind::Real => {
            let real = RealOptions {
                spin_margin: cfg.spin_margin,
                phase_offsets: cfg.phase_offsets.to_vec(),
                rt_priority: cfg.rt_priority,
                on_tick: opts.on_node_tick.clone(),
                pause: None,
            };
            let r = run_real(nodes, cfg.duration, &opts.stop, &real);
            (r.end, Some(r.timing))
        }
    };
    let wall = start.elapsed();
    let metrics = summarize(cfg, &handles, &end, timing);
    let trace = std::mem::take(&mut lock(&handles.log).trace);
    Ok(RunReport {
        metrics,
        trace,
        end,
        wall,
    })
}

/// The summary of a finished (or running) graph, from its handles.
pub fn summarize(
    cfg: &RunConfig,
    h: &GraphHandles,
    end: &RunEnd,
    timing: Option<Vec<NodeTiming>>,
) -> Metrics {
    let log = lock(&h.log);
    let obs = h.obs.stats();
    let action = h.action.stats();
    let sim_time = log.fell_at.unwrap_or(end.at);
    let per_s = |n: u64| {
        if sim_time.0 == 0 {
            0.0
        } else {
            round_to(n as f64 / sim_time.as_secs_f64(), 3)
        }
    };
    let (p50, p99, max) = log.latency.summary_ms();
    Metrics {
        balanced: log.fell_at.is_none(),
        clock: cfg.clock.as_str().to_string(),
        control_hz: cfg.control_hz,
        sensor_hz: cfg.sensor_hz,
        actuator_hz: cfg.actuator_hz,
        queue_depth: cfg.queue_depth,
        seed: cfg.seed,
        duration_s: cfg.duration.as_secs_f64(),
        steps: log.steps,
        sim_time_s: sim_time.as_secs_f64(),
        final_pole_angle: log
            .last
            .map_or_else(|| lock(&h.plant).state().theta, |r| r.pole_angle),
        mean_latency_ms: round_to(log.latency.mean().unwrap_or(0.0) / 1e6, 6),
        latency_p50_ms: p50,
        latency_p99_ms: p99,
        latency_max_ms: max,
        obs_published: obs.published,
        obs_dropped: obs.dropped,
        obs_msg_per_s: per_s(obs.published),
        action_published: action.published,
        action_dropped: action.dropped,
        action_msg_per_s: per_s(action.published),
        fell_at_s: log.fell_at.map(Nanos::as_secs_f64),
        policy: h.brain.label(),
        nonfinite_actions: log.nonfinite_actions,
        node_timing: timing,
    }
}
