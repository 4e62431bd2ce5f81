//! A run's figures (`metrics.json`, [`ratelab_core::metrics::Metrics`]) from its graph's state at
//! the end: [`GraphState`] (what is read of a graph, as data: one process's or the whole
//! graph's) and [`summarize_state`].

use crate::config::RunConfig;
use crate::graph::{lock, GraphHandles, GraphSpec, NodeId, TopicId};
use crate::scheduler::RunEnd;
use ratelab_core::metrics::{round_to, Metrics, NodeMetrics, NodeTiming, TopicMetrics};
use ratelab_core::msg::AnyTopic;
use ratelab_core::time::Nanos;

/// What [`summarize`] reads of a graph, as data: the whole graph's state when it ran in one
/// process, or one process's view of it under `ratelab launch --processes` (sent to the
/// launcher as JSON and merged there, `ratelab::distributed`). Vectors are indexed by
/// [`crate::graph::NodeId`] / [`crate::graph::TopicId`].
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GraphState {
    /// Each topic's counters at the end.
    pub topics: Vec<ratelab_core::topic::TopicStats>,
    /// Each topic's QoS in force at the end.
    pub topic_qos: Vec<ratelab_core::qos::TopicQos>,
    /// Each topic's subscriptions' counters at the end, when some topic has several
    /// subscribers (empty when none has).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub subscriptions: Vec<Vec<ratelab_core::topic::TopicStats>>,
    /// Each node's liveliness lease and status at the end.
    pub liveliness: Vec<(Option<Nanos>, ratelab_core::qos::LivelinessStatus)>,
    /// Each node's rate at the end, Hz.
    pub rates_hz: Vec<f64>,
    /// Each node's tick count (empty when unknown).
    pub ticks: Vec<u64>,
    /// Real clock: each node's tick timing.
    pub timing: Option<Vec<NodeTiming>>,
    /// What the executors measured, when the graph has executors or compute times
    /// ([`ratelab_core::executor`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exec: Option<ratelab_core::executor::ExecFigures>,
    /// The brain's label.
    pub brain: String,
    /// What the actuator measured.
    pub actuator: ActuatorSummary,
    /// The faults injected by command while the run went on
    /// ([`crate::command::Command::InjectFault`]), besides those of its settings.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub injected_faults: Vec<ratelab_core::qos::Fault>,
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
    /// The estimator's figures against the truth, when the graph has one
    /// ([`ratelab_core::estimate`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate: Option<ratelab_core::estimate::EstimateFigures>,
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
            topics: h.topic_stats_at(at).iter().copied().collect(),
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
            injected_faults: h.faults.injected(),
            actuator: ActuatorSummary {
                steps: log.steps,
                fell_at: log.fell_at,
                watchdog: log.watchdog.as_ref().map(ToString::to_string),
                mean_latency_ms: round_to(log.latency.mean().unwrap_or(0.0) / 1e6, 6),
                latency_ms: log.latency.summary_ms(),
                final_pole_angle: log
                    .last
                    .as_ref()
                    .map_or_else(|| lock(&h.plant).state().theta, |r| r.pole_angle),
                nonfinite_actions: log.nonfinite_actions,
                estimate: log.estimate.figures(),
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
    exec: Option<ratelab_core::executor::ExecFigures>,
) -> Metrics {
    let mut st = GraphState::capture(h, end.at, ticks, timing);
    st.exec = exec;
    summarize_state(cfg, &st, end)
}

/// The summary (`metrics.json`) of a graph's [`GraphState`] at the end of a run.
pub fn summarize_state(cfg: &RunConfig, st: &GraphState, end: &RunEnd) -> Metrics {
    let spec = &cfg.graph;
    let log = &st.actuator;
    let stats: ratelab_core::runlog::TopicCounters = st.topics.iter().copied().collect();
    let chain = spec.chain;
    // The chain's topics as its reader sees them: with several subscribers, the queue of the
    // policy (for /obs) and of the node it drives (for /action).
    let as_read_by = |t: TopicId, reader: NodeId| -> ratelab_core::topic::TopicStats {
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
    let nodes = node_metrics(cfg, st);
    let topics = topic_metrics(spec, st, &stats, &per_s);
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
            .filter(|e| e.kind != ratelab_core::executor::ExecutorKind::PerNode)
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
        estimate: spec.estimate_topic().zip(log.estimate.clone()).map(|(t, figures)| {
            ratelab_core::estimate::EstimateReport {
                estimator: spec.node(spec.topic(t).publisher).name.clone(),
                topic: spec.topic(t).name.clone(),
                truth: ratelab_core::estimate::TRUTH.to_string(),
                figures,
            }
        }),
    }
}

/// Each node's figures by name: rate, ticks, lateness, liveliness, faults, compute and
/// executor figures, as the run ended.
fn node_metrics(
    cfg: &RunConfig,
    st: &GraphState,
) -> std::collections::BTreeMap<String, NodeMetrics> {
    cfg.graph
        .nodes
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let t = st.timing.as_ref().and_then(|t| t.get(i));
            // Liveliness as it ended (the lease may have been set live, after the start).
            let live = st.liveliness.get(i);
            let status = live.map(|l| l.1);
            let lease = n.liveliness_lease.or(live.and_then(|l| l.0));
            let faults = || {
                (cfg.faults.iter())
                    .chain(&st.injected_faults)
                    .filter(|f| f.node == n.name)
            };
            let faulted = faults().next().is_some();
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
                faults: faults()
                    .map(ratelab_core::metrics::FaultMetrics::from)
                    .collect(),
            };
            (n.name.clone(), m)
        })
        .collect()
}

/// Each topic's figures by name: its counters (`stats`, as the holder counted them), its
/// subscriptions' where it has several, its rate (`per_s`: messages per second of the run)
/// and its QoS as the run ended.
fn topic_metrics(
    spec: &GraphSpec,
    st: &GraphState,
    stats: &ratelab_core::runlog::TopicCounters,
    per_s: &dyn Fn(u64) -> f64,
) -> std::collections::BTreeMap<String, TopicMetrics> {
    spec.topics
        .iter()
        .zip(stats.iter())
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
                                let m = ratelab_core::metrics::SubscriptionMetrics {
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
                incompatible_qos: incompatible_qos(spec, st, TopicId(i), now_qos, s),
                late_joiners: late_joiners(spec, st, TopicId(i), now_qos, s),
            };
            (t.name.clone(), m)
        })
        .collect()
}

/// Topic `t`'s subscriptions left unconnected by what they requested, by node: those the
/// QoS at the end (`now_qos`) does not meet, and those that missed messages while a QoS in
/// force earlier did not (`unmatched`). The event names what failed at the end, or else
/// at the start.
fn incompatible_qos(
    spec: &GraphSpec,
    st: &GraphState,
    t: TopicId,
    now_qos: ratelab_core::qos::TopicQos,
    stats: &ratelab_core::topic::TopicStats,
) -> std::collections::BTreeMap<String, ratelab_core::metrics::IncompatibleQos> {
    let topic = spec.topic(t);
    if topic.requested.is_empty() {
        return Default::default();
    }
    let at_end = spec.incompatible(t, &now_qos);
    let at_start = spec.incompatible(t, &topic.qos);
    topic
        .subscribers
        .iter()
        .enumerate()
        .filter_map(|(k, &n)| {
            let not_delivered = own_stats(st, t, k, stats).map_or(0, |s| s.unmatched);
            let failed = at_end
                .iter()
                .chain(&at_start)
                .find(|(b, ..)| *b == k)
                .map(|(.., m)| m.clone());
            if failed.is_none() && not_delivered == 0 {
                return None;
            }
            let m = failed.unwrap_or_default();
            let i = ratelab_core::metrics::IncompatibleQos {
                policy: m.first().map_or("", |m| m.policy.as_str()).to_string(),
                event: if m.is_empty() {
                    "incompatible QoS for part of the run".to_string()
                } else {
                    ratelab_core::qos::compat::event_text(&m)
                },
                not_delivered,
            };
            Some((spec.node(n).name.clone(), i))
        })
        .collect()
}

/// Topic `t`'s subscriptions whose nodes joined late (`start_ms`), by node: when, and how
/// many messages from before they received as they joined (`history_on_join`).
fn late_joiners(
    spec: &GraphSpec,
    st: &GraphState,
    t: TopicId,
    now_qos: ratelab_core::qos::TopicQos,
    stats: &ratelab_core::topic::TopicStats,
) -> std::collections::BTreeMap<String, ratelab_core::metrics::LateJoiner> {
    let topic = spec.topic(t);
    topic
        .subscribers
        .iter()
        .enumerate()
        .filter_map(|(k, &n)| {
            let start = spec.node(n).start?;
            let mine = own_stats(st, t, k, stats);
            let history = mine.and_then(|s| s.history_on_join).unwrap_or(0);
            let missed = mine.map_or(0, |s| s.before_join);
            let j = ratelab_core::metrics::LateJoiner {
                start_s: round_to(start.as_secs_f64(), 6),
                history,
                durability: now_qos.durability.as_str().to_string(),
                missed,
            };
            Some((spec.node(n).name.clone(), j))
        })
        .collect()
}

/// Subscription `k` of topic `t`'s own counters: its queue's when the topic has several
/// (`st.subscriptions`), else the topic's, `stats`.
fn own_stats<'a>(
    st: &'a GraphState,
    t: TopicId,
    k: usize,
    stats: &'a ratelab_core::topic::TopicStats,
) -> Option<&'a ratelab_core::topic::TopicStats> {
    match st.subscriptions.get(t.0).filter(|s| s.len() > 1) {
        Some(subs) => subs.get(k),
        None => Some(stats),
    }
}
