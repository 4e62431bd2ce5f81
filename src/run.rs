//! One run, end to end: settings + brain → plant, graph, executor → [`RunReport`].

use crate::config::{ClockKind, RunConfig};
use crate::graph::{lock, Graph, GraphHandles, NodeId, StepObserver, TopicId};
use crate::metrics::{round_to, Metrics, NodeMetrics, NodeTiming, TopicMetrics};
use crate::msg::AnyTopic;
use crate::plant::{CartPole, PlantError};
use crate::policy::{BrainSlot, Policy};
use crate::runlog::StepRecord;
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
    /// The graph could not be offered to ROS 2 (`--ros2`).
    #[error(transparent)]
    Ros2(#[from] crate::ros2::Ros2Error),
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
    /// Set every topic's history depth.
    SetQueueDepth {
        /// New depth (≥ 1).
        depth: usize,
    },
    /// Set one node's rate, Hz.
    SetNodeHz {
        /// The node's name.
        node: String,
        /// New rate.
        hz: f64,
    },
    /// Set one topic's history depth.
    SetTopicDepth {
        /// The topic's name.
        topic: String,
        /// New depth (≥ 1).
        depth: usize,
    },
    /// Set one topic's QoS keys (`KEY=VALUE[,KEY=VALUE…]`, the graph file's keys; see
    /// [`crate::qos`]): the lab's `f` (delivery), `d` (deadline) and `L` (link loss).
    SetTopicQos {
        /// The topic's name.
        topic: String,
        /// The keys and values.
        pairs: String,
    },
    /// Swap the policy node's brain (`scripted` or a checkpoint path).
    SetPolicy {
        /// The brain spec, as `--policy` takes it.
        spec: String,
    },
    /// Run the graph on other executors, as `--executor` takes them (`per_node`,
    /// `single_threaded`, `multi_threaded:N`): the lab's `x`. Under the virtual clock it
    /// takes effect at the instant it is applied (ticks running keep their threads); under
    /// the real clock, whose threads are made when a run starts, from the next run.
    SetExecutor {
        /// The executors, as `--executor` takes them.
        executor: String,
    },
}

impl Command {
    /// Apply to the settings a run starts with: `graph`'s rates and depths, the brain
    /// spec `policy`. The checks are the command line's: rates in (0, 10 000] Hz (the
    /// actuator at 50), depths in 1..=[`crate::qos::MAX_DEPTH`], names that exist.
    /// A brain is not loaded here (see [`Command::validate`]).
    ///
    /// # Errors
    /// One line saying what is wrong; nothing changes.
    pub fn apply_to_settings(
        &self,
        graph: &mut crate::graph::GraphSpec,
        policy: &mut String,
    ) -> Result<(), String> {
        match self {
            Command::SetControlHz { hz } => crate::config::check_rate("control-hz", *hz)
                .and_then(|_| {
                    let id = graph.chain_for("the control rate")?.policy;
                    Ok(graph.set_rate_of(id, *hz)?)
                })
                .map_err(|e| e.to_string()),
            Command::SetSensorHz { hz } => crate::config::check_rate("sensor-hz", *hz)
                .and_then(|_| {
                    let id = graph.chain_for("the sensor rate")?.sensor;
                    Ok(graph.set_rate_of(id, *hz)?)
                })
                .map_err(|e| e.to_string()),
            Command::SetQueueDepth { depth } => {
                graph.set_all_depths(*depth).map_err(|e| e.to_string())
            }
            Command::SetNodeHz { node, hz } => graph.set_rate(node, *hz).map_err(|e| e.to_string()),
            Command::SetTopicDepth { topic, depth } => {
                graph.set_depth(topic, *depth).map_err(|e| e.to_string())
            }
            Command::SetTopicQos { topic, pairs } => {
                graph.set_qos(topic, pairs).map_err(|e| e.to_string())
            }
            Command::SetPolicy { spec } => {
                policy.clone_from(spec);
                Ok(())
            }
            Command::SetExecutor { executor } => {
                graph.set_executor(crate::executor::ExecutorOverride::parse(executor)?);
                Ok(())
            }
        }
    }

    /// Check the command against `graph` as the command line checks the same values
    /// ([`Command::apply_to_settings`] on a copy), and that a brain it names loads.
    ///
    /// # Errors
    /// One line saying what is wrong.
    pub fn validate(&self, graph: &crate::graph::GraphSpec) -> Result<(), String> {
        self.apply_to_settings(&mut graph.clone(), &mut String::new())?;
        if let Command::SetPolicy { spec } = self {
            crate::checkpoint::load_policy(spec).map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    /// Apply to a running graph.
    ///
    /// # Errors
    /// A one-line description when the value is invalid or the brain cannot be loaded
    /// (the graph is unchanged).
    pub fn apply(&self, h: &GraphHandles) -> Result<(), String> {
        match self {
            Command::SetControlHz { hz } => h
                .control_rate()
                .ok_or("the graph has no chapter chain: no control rate")?
                .set_hz(*hz)
                .map_err(|e| e.to_string()),
            Command::SetSensorHz { hz } => h
                .sensor_rate()
                .ok_or("the graph has no chapter chain: no sensor rate")?
                .set_hz(*hz)
                .map_err(|e| e.to_string()),
            Command::SetQueueDepth { depth } => {
                h.set_queue_depth(*depth).map_err(|e| e.to_string())
            }
            Command::SetNodeHz { node, hz } => {
                // The file's rules (the actuator's fixed rate) hold for live changes too.
                let mut spec = h.spec.as_ref().clone();
                spec.set_rate(node, *hz).map_err(|e| e.to_string())?;
                let id = spec.node_id(node).expect("set_rate found it");
                h.rate(id).set_hz(*hz).map_err(|e| e.to_string())
            }
            Command::SetTopicDepth { topic, depth } => {
                let id = h
                    .spec
                    .topic_id(topic)
                    .ok_or_else(|| format!("no topic '{topic}' in graph '{}'", h.spec.name))?;
                h.topic(id).set_depth(*depth).map_err(|e| e.to_string())
            }
            Command::SetTopicQos { topic, pairs } => {
                // The file's rules hold for live changes: check on the graph as it is now.
                let mut spec = h.current_spec();
                spec.set_qos(topic, pairs).map_err(|e| e.to_string())?;
                let id = spec.topic_id(topic).expect("set_qos found it");
                let t = spec.topic(id);
                h.topic(id).set_depth(t.depth).map_err(|e| e.to_string())?;
                h.topic(id).set_qos(t.qos);
                Ok(())
            }
            Command::SetPolicy { spec } => {
                let brain = crate::checkpoint::load_policy(spec).map_err(|e| e.to_string())?;
                h.brain.swap(brain);
                Ok(())
            }
            Command::SetExecutor { executor } => {
                let over = crate::executor::ExecutorOverride::parse(executor)?;
                let mut spec = h.current_spec();
                spec.set_executor(over);
                *crate::graph::lock(&h.executor) = Some(over);
                *crate::graph::lock(&h.plan_request) = Some(spec.execution_plan());
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
    /// Virtual clock, when executors or compute times apply: told about every tick as its
    /// executor ran it (release, start, end).
    pub on_span: Option<crate::executor::SpanHook>,
    /// Offer the graph to ROS 2 while it runs ([`crate::ros2`]). Under the virtual clock the
    /// run then keeps pace with the wall clock (one second of run time per second), so
    /// that ROS 2's tools see the graph's rates; its results are unchanged.
    pub ros2: Option<crate::ros2::Ros2Options>,
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
    pub ros2: Option<crate::ros2::BridgeReport>,
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
    Ok(Graph::build(
        &cfg.graph,
        plant,
        brain,
        cfg.seed,
        keep_trace,
        observers,
        &cfg.faults,
    )?)
}

/// The virtual-clock executor for `cfg`'s graph: its phase offsets and execution plan
/// (executors, callback groups); response times are measured when the graph has executors
/// or compute times.
pub fn virtual_scheduler(
    cfg: &RunConfig,
    nodes: &[Box<dyn crate::node::Node>],
) -> VirtualScheduler {
    VirtualScheduler::with_plan(
        nodes,
        &cfg.phase_offsets,
        cfg.graph.execution_plan(),
        cfg.graph.has_executors_or_compute(),
    )
}

/// The real-clock executor's options for `cfg`: its spin margin, phase offsets, real-time
/// priority and execution plan (measuring when the graph has executors or compute times);
/// no tick hook, no pause, time zero when the run starts.
pub fn real_options(cfg: &RunConfig) -> RealOptions {
    RealOptions {
        spin_margin: cfg.spin_margin,
        phase_offsets: cfg.phase_offsets.to_vec(),
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
/// the run with [`crate::scheduler::EndReason::NodeFailed`] instead: the report has what
/// was measured up to then.
pub fn run(
    cfg: &RunConfig,
    brain: Box<dyn Policy>,
    opts: RunOptions,
) -> Result<RunReport, RunError> {
    if opts.ros2.is_none() {
        crate::ros2::external::check_offered(&cfg.graph).map_err(crate::ros2::Ros2Error::Usage)?;
    }
    // Under the virtual clock the run core steps the graph; under the real clock, one
    // thread per node.
    let driver = match cfg.clock {
        ClockKind::Virtual => Driver::Virtual(Box::new(crate::runcore::RunCore::new(
            cfg,
            brain,
            crate::runcore::CoreOptions {
                keep_trace: opts.keep_trace,
                observers: opts.observers,
                commands: opts.commands.clone(),
                on_span: opts.on_span.clone(),
                remake_brain: None,
            },
        )?)),
        ClockKind::Real => {
            let brain = BrainSlot::new(brain);
            Driver::Real(build_graph(cfg, brain, opts.keep_trace, opts.observers)?)
        }
    };
    let handles = match &driver {
        Driver::Virtual(core) => core.handles().clone(),
        Driver::Real(g) => g.handles.clone(),
    };
    let link = match &opts.ros2 {
        Some(o) => {
            // What needs no network is refused before a session (or a router) opens.
            crate::ros2::bridge::check(&cfg.graph, o).map_err(crate::ros2::Ros2Error::Usage)?;
            let env = crate::ros2::session::SessionEnv::from_process();
            Some(crate::ros2::session::open(&env, &opts.stop)?)
        }
        None => None,
    };
    let bridge = match (&opts.ros2, &link) {
        (Some(o), Some(link)) => {
            let offer = crate::ros2::bridge::Offer::whole(&handles);
            let b = crate::ros2::Bridge::start(link, &offer, o, cfg.clock, &opts.stop)?;
            eprintln!("[ratelab] {}", b.describe());
            Some(b)
        }
        _ => None,
    };
    let start = Instant::now();
    let (end, ticks, timing, exec) = match driver {
        Driver::Virtual(mut core) => {
            let end = loop {
                if opts.stop.is_stopped() {
                    break core.interrupt();
                }
                if let (Some(b), Some(t)) = (&bridge, core.next_instant()) {
                    // Keep pace with the wall clock, then tell ROS 2 the time.
                    let due = start + Duration::from_nanos(t.0);
                    if let Some(wait) = due.checked_duration_since(Instant::now()) {
                        std::thread::sleep(wait);
                    }
                    b.clock(t);
                }
                if let crate::runcore::Step::Ended(end) = core.step() {
                    break end;
                }
            };
            let exec = core.scheduler().figures(end.at);
            (end, core.scheduler().ticks().to_vec(), None, exec)
        }
        Driver::Real(Graph { nodes, .. }) => {
            let real = RealOptions {
                on_tick: opts.on_node_tick.clone(),
                ..real_options(cfg)
            };
            let r = run_real(nodes, cfg.duration, &opts.stop, &real);
            let ticks = r.timing.iter().map(|t| t.ticks).collect();
            (r.end, ticks, Some(r.timing), r.exec)
        }
    };
    let wall = start.elapsed();
    let ros2 = bridge.map(crate::ros2::Bridge::finish);
    if let Some(link) = link {
        link.close();
    }
    let metrics = summarize(cfg, &handles, &end, &ticks, timing, exec);
    let trace = std::mem::take(&mut lock(&handles.log).trace);
    Ok(RunReport {
        metrics,
        trace,
        end,
        wall,
        ros2,
    })
}

/// What steps a run's graph: the run core under the virtual clock, one thread per node
/// under the real clock.
enum Driver {
    Virtual(Box<crate::runcore::RunCore>),
    Real(Graph),
}

/// What [`summarize`] reads of a graph, as data: the whole graph's state when it ran in one
/// process, or one process's view of it under `ratelab launch --processes` (sent to the
/// launcher as JSON and merged there, [`crate::distributed`]). Vectors are indexed by
/// [`crate::graph::NodeId`] / [`crate::graph::TopicId`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GraphState {
    /// Each topic's counters at the end.
    pub topics: Vec<crate::topic::TopicStats>,
    /// Each topic's QoS in force at the end.
    pub topic_qos: Vec<crate::qos::TopicQos>,
    /// Each topic's subscriptions' counters at the end, when some topic has several
    /// subscribers (empty when none has).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub subscriptions: Vec<Vec<crate::topic::TopicStats>>,
    /// Each node's liveliness lease and status at the end.
    pub liveliness: Vec<(Option<Nanos>, crate::qos::LivelinessStatus)>,
    /// Each node's rate at the end, Hz.
    pub rates_hz: Vec<f64>,
    /// Each node's tick count (empty when unknown).
    pub ticks: Vec<u64>,
    /// Real clock: each node's tick timing.
    pub timing: Option<Vec<NodeTiming>>,
    /// What the executors measured, when the graph has executors or compute times
    /// ([`crate::executor`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exec: Option<crate::executor::ExecFigures>,
    /// The brain's label.
    pub brain: String,
    /// What the actuator measured.
    pub actuator: ActuatorSummary,
}

/// The actuator's figures in a [`GraphState`] (ms values rounded as `metrics.json` prints them).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ActuatorSummary {
    /// Actuator ticks.
    pub steps: u64,
    /// Run time of the fall.
    pub fell_at: Option<Nanos>,
    /// The watchdog's verdict, as printed.
    pub watchdog: Option<String>,
    /// Sense→act latency mean, ms (6 decimals).
    pub mean_latency_ms: f64,
    /// Sense→act latency p50, p99 and max, ms (3 decimals).
    pub latency_ms: (f64, f64, f64),
    /// The pole angle at the last step (or the plant's, before any), rad.
    pub final_pole_angle: f64,
    /// Ticks whose newest action was non-finite.
    pub nonfinite_actions: u64,
}

impl GraphState {
    /// The state of the graph behind `h` at run time `at`, with each node's `ticks` (by node
    /// index; empty when unknown) and real-clock `timing`.
    pub fn capture(
        h: &GraphHandles,
        at: Nanos,
        ticks: &[u64],
        timing: Option<Vec<NodeTiming>>,
    ) -> GraphState {
        let log = lock(&h.log);
        GraphState {
            topics: h.topic_stats_at(at).as_slice().to_vec(),
            topic_qos: h.topics.iter().map(AnyTopic::qos).collect(),
            subscriptions: if h.spec.topics.iter().any(|t| t.subscribers.len() > 1) {
                h.topics
                    .iter()
                    .map(|t| t.subscription_stats(Some(at)))
                    .collect()
            } else {
                Vec::new()
            },
            liveliness: h
                .liveliness
                .iter()
                .map(|l| (l.lease(), l.status_at(at)))
                .collect(),
            rates_hz: h.rates_hz(),
            ticks: ticks.to_vec(),
            timing,
            exec: None,
            brain: h.brain_label(),
            actuator: ActuatorSummary {
                steps: log.steps,
                fell_at: log.fell_at,
                watchdog: log.watchdog.as_ref().map(ToString::to_string),
                mean_latency_ms: round_to(log.latency.mean().unwrap_or(0.0) / 1e6, 6),
                latency_ms: log.latency.summary_ms(),
                final_pole_angle: log
                    .last
                    .map_or_else(|| lock(&h.plant).state().theta, |r| r.pole_angle),
                nonfinite_actions: log.nonfinite_actions,
            },
        }
    }
}

/// The summary of a finished (or running) graph, from its handles. `ticks` holds each
/// node's tick count (by node index; empty when unknown).
pub fn summarize(
    cfg: &RunConfig,
    h: &GraphHandles,
    end: &RunEnd,
    ticks: &[u64],
    timing: Option<Vec<NodeTiming>>,
    exec: Option<crate::executor::ExecFigures>,
) -> Metrics {
    let mut st = GraphState::capture(h, end.at, ticks, timing);
    st.exec = exec;
    summarize_state(cfg, &st, end)
}

/// The summary (`metrics.json`) of a graph's [`GraphState`] at the end of a run.
pub fn summarize_state(cfg: &RunConfig, st: &GraphState, end: &RunEnd) -> Metrics {
    let spec = &cfg.graph;
    let log = &st.actuator;
    let stats: crate::runlog::TopicCounters = st.topics.iter().copied().collect();
    let chain = spec.chain;
    // The chain's topics as its reader sees them: with several subscribers, the queue of the
    // policy (for /obs) and of the node it drives (for /action).
    let as_read_by = |t: TopicId, reader: NodeId| -> crate::topic::TopicStats {
        let k = spec.topic(t).subscribers.iter().position(|&s| s == reader);
        k.and_then(|k| st.subscriptions.get(t.0)?.get(k).copied())
            .filter(|_| spec.topic(t).subscribers.len() > 1)
            .unwrap_or_else(|| stats.get(t))
    };
    let obs = chain.map(|c| as_read_by(c.obs, c.policy));
    let action = chain.map(|c| {
        let subs = &spec.topic(c.action).subscribers;
        let reader = if subs.contains(&spec.actuator) {
            spec.actuator
        } else {
            subs.first().copied().unwrap_or(spec.actuator)
        };
        as_read_by(c.action, reader)
    });
    let sim_time = log.fell_at.unwrap_or(end.at);
    let per_s = |n: u64| {
        if sim_time.0 == 0 {
            0.0
        } else {
            round_to(n as f64 / sim_time.as_secs_f64(), 3)
        }
    };
    let (p50, p99, max) = log.latency_ms;
    let nodes: std::collections::BTreeMap<String, NodeMetrics> = spec
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let t = st.timing.as_ref().and_then(|t| t.get(i));
            // Liveliness as it ended (the lease may have been set live, after the start).
            let live = st.liveliness.get(i);
            let status = live.map(|l| l.1);
            let lease = n.liveliness_lease.or(live.and_then(|l| l.0));
            let faulted = cfg.faults.iter().any(|f| f.node == n.name);
            let x = st.exec.as_ref().and_then(|x| x.nodes.get(i));
            let m = NodeMetrics {
                compute_ms: n.compute.map(|c| c.mean.as_millis_f64()),
                compute_jitter_ms: n
                    .compute
                    .filter(|c| c.jitter.0 > 0)
                    .map(|c| c.jitter.as_millis_f64()),
                exec: x.cloned(),
                kind: n.kind_name().to_string(),
                rank: i,
                rate_hz: n.rate_hz,
                rate_hz_end: st.rates_hz.get(i).copied().filter(|end| *end != n.rate_hz),
                ticks: st.ticks.get(i).copied().unwrap_or(0),
                lateness_p99_us: t.map(|t| t.lateness_p99_us),
                lateness_max_us: t.map(|t| t.lateness_max_us),
                liveliness_lease_ms: lease.map(Nanos::as_millis_f64),
                not_alive: status.and_then(|s| lease.map(|_| s.not_alive)),
                faulted_ticks: status.and_then(|s| faulted.then_some(s.faulted_ticks)),
                faults: cfg
                    .faults
                    .iter()
                    .filter(|f| f.node == n.name)
                    .map(crate::metrics::FaultMetrics::from)
                    .collect(),
            };
            (n.name.clone(), m)
        })
        .collect();
    let topics = spec
        .topics
        .iter()
        .zip(stats.as_slice())
        .enumerate()
        .map(|(i, (t, s))| {
            let now_qos = st.topic_qos.get(i).copied().unwrap_or(t.qos);
            let m = TopicMetrics {
                msg: t.msg.as_str().to_string(),
                publisher: spec.node(t.publisher).name.clone(),
                subscriber: t.subscriber().map(|n| spec.node(n).name.clone()),
                subscriptions: st
                    .subscriptions
                    .get(i)
                    .filter(|subs| subs.len() > 1)
                    .map(|subs| {
                        t.subscribers
                            .iter()
                            .zip(subs)
                            .map(|(n, s)| {
                                let m = crate::metrics::SubscriptionMetrics {
                                    dropped: s.dropped,
                                    stale_reads: s.stale_reads,
                                    lost: s.lost,
                                };
                                (spec.node(*n).name.clone(), m)
                            })
                            .collect()
                    })
                    .unwrap_or_default(),
                depth: s.depth,
                published: s.published,
                dropped: s.dropped,
                stale_reads: s.stale_reads,
                msg_per_s: per_s(s.published),
                qos: (!(t.qos.is_default() && now_qos.is_default()))
                    .then(|| now_qos.short(s.depth)),
                qos_counters: s
                    .reported(&[t.qos, now_qos])
                    .into_iter()
                    .map(|c| (c.key().to_string(), s.counter(c)))
                    .collect(),
            };
            (t.name.clone(), m)
        })
        .collect();
    let node_failed = match &end.reason {
        crate::scheduler::EndReason::NodeFailed { node, message } => {
            Some(format!("{node}: {message}"))
        }
        _ => None,
    };
    // An actuator killed during the run stood the plant still from then to the end (the
    // headline says so by the same rule, `FaultMetrics::kills_by`).
    let actuator_killed = nodes
        .get(&spec.node(spec.actuator).name)
        .is_some_and(|a| a.faults.iter().any(|f| f.kills_by(sim_time.as_secs_f64())));
    Metrics {
        // A plant that never stepped balanced nothing (an actuator stalled or killed from the
        // start), nor one whose actuator was killed: not `balanced`.
        balanced: log.fell_at.is_none()
            && node_failed.is_none()
            && log.watchdog.is_none()
            && log.steps > 0
            && !actuator_killed,
        stopped_by_watchdog: log.watchdog.clone(),
        without_chain: chain.is_none().then(|| {
            format!(
                "graph '{}' has no sensor → policy → actuator chain: the chapter's figures (control_hz, sensor_hz, queue_depth, policy_ticks, obs_*, action_*) are left out; its nodes and topics have their own",
                spec.name
            )
        }),
        missing_processes: Vec::new(),
        executors: st
            .exec
            .iter()
            .flat_map(|x| &x.executors)
            .filter(|e| e.kind != crate::executor::ExecutorKind::PerNode)
            .cloned()
            .collect(),
        clock: cfg.clock.as_str().to_string(),
        control_hz: cfg.control_hz(),
        sensor_hz: cfg.sensor_hz(),
        actuator_hz: cfg.actuator_hz(),
        queue_depth: cfg.queue_depth(),
        seed: cfg.seed,
        duration_s: cfg.duration.as_secs_f64(),
        steps: log.steps,
        actuator_steps: log.steps,
        // The brain's runs: the policy's ticks less those a fault (`--stall`) swallowed.
        policy_ticks: chain.map(|c| {
            st.ticks
                .get(c.policy.0)
                .copied()
                .unwrap_or(0)
                .saturating_sub(st.liveliness.get(c.policy.0).map_or(0, |l| l.1.faulted_ticks))
        }),
        control_hz_end: chain.and_then(|c| {
            st.rates_hz
                .get(c.policy.0)
                .copied()
                .or(cfg.control_hz())
        }),
        sim_time_s: sim_time.as_secs_f64(),
        final_pole_angle: log.final_pole_angle,
        mean_latency_ms: log.mean_latency_ms,
        latency_p50_ms: p50,
        latency_p99_ms: p99,
        latency_max_ms: max,
        obs_published: obs.map(|o| o.published),
        obs_dropped: obs.map(|o| o.dropped),
        obs_msg_per_s: obs.map(|o| per_s(o.published)),
        action_published: action.map(|a| a.published),
        action_dropped: action.map(|a| a.dropped),
        action_msg_per_s: action.map(|a| per_s(a.published)),
        fell_at_s: log.fell_at.map(Nanos::as_secs_f64),
        policy: st.brain.clone(),
        nonfinite_actions: log.nonfinite_actions,
        node_timing: st.timing.clone(),
        node_failed,
        graph: spec.name.clone(),
        nodes,
        topics,
    }
}
