//! The graph: nodes at fixed rates exchanging messages on topics, around one cartpole.
//!
//! Its shape is data: a [`GraphSpec`] read from a graph file ([`spec`]; the chapter's
//! sensor → `/obs` → policy → `/action` → actuator is `graphs/cartpole.toml`, the default).
//! [`Graph::build`] turns a spec into runnable nodes ([`nodes`]) and the [`GraphHandles`]
//! every view uses (rates, topics, brain, plant, the run log), all indexed by the spec's
//! [`NodeId`]/[`TopicId`]. A node or brain in another language (a learner's Python) is made
//! by the interpreter its layer installs ([`interpreter`]).

pub mod estimator;
pub mod faults;
pub mod interpreter;
pub mod kind;
pub mod nodes;
pub mod registry;
pub mod spec;
pub mod synthetic;

use crate::plant::CartPole;
pub use crate::plant::SharedPlant;
use crate::policy::BrainSlot;
use kind::{AdapterParts, BuildContext, Code, NodeContext, RunParts};
pub use kind::{Kind, KindDef};
use nodes::{ExternalPort, GraphNode, NodeCore};
use ratelab_core::executor::ComputeDraw;
use ratelab_core::msg::AnyTopic;
use ratelab_core::publisher::Outbox;
use ratelab_core::qos::{Fault, Liveliness};
use ratelab_core::rate::{InvalidRate, Rate};
use ratelab_core::runlog::{RunLog, StepRecord, StepSink, TopicCounters};
use ratelab_core::topic::ZeroDepth;
pub use spec::{Chain, GraphSpec, MsgType, NodeId, TopicId};
use std::sync::{Arc, Mutex, MutexGuard};

/// Lock a shared value, tolerating poison (each holder leaves it consistent).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Something told about every actuator tick (a recorder, the lab's telemetry).
/// Called on the actuator's thread, before the run log ([`GraphHandles::log`]) takes the
/// step: it must not block.
pub trait StepObserver: Send {
    /// The graph was built: a chance to keep handles (rates, topics) for later ticks.
    fn attach(&mut self, _handles: &GraphHandles) {}
    /// One actuator tick happened.
    fn on_step(&mut self, rec: &StepRecord);
}

/// A [`StepObserver`] as the actuator sees it.
struct Observer(Box<dyn StepObserver>);

impl StepSink for Observer {
    fn on_step(&mut self, rec: &StepRecord) {
        self.0.on_step(rec);
    }
}

/// Handles to change and read a running graph: rates, depths, the brain. Cheap to clone
/// and `Send`, so the lab's thread can hold one while the graph runs elsewhere.
#[derive(Clone)]
pub struct GraphHandles {
    /// The graph's shape (rates and depths as the run started).
    pub spec: Arc<GraphSpec>,
    /// Each node's rate, by [`NodeId`].
    pub rates: Vec<Rate>,
    /// Each topic, by [`TopicId`].
    pub topics: Vec<AnyTopic>,
    /// The brain every policy node runs.
    pub brain: BrainSlot,
    /// The plant.
    pub plant: SharedPlant,
    /// What the actuator measured.
    pub log: Arc<Mutex<RunLog>>,
    /// Each node's liveliness, by [`NodeId`].
    pub liveliness: Vec<Arc<Liveliness>>,
    /// The executors asked for while running (`Command::SetExecutor`): the override, for
    /// [`GraphHandles::current_spec`]…
    pub executor: Arc<Mutex<Option<ratelab_core::executor::ExecutorOverride>>>,
    /// …and the plan the virtual scheduler takes at its next instant.
    pub plan_request: ratelab_core::executor::PlanRequest,
    /// The phase changes asked for while running (`Command::SetPhase`), which the virtual
    /// scheduler takes before its next instant.
    pub phase_request: Arc<PhaseRequests>,
    /// The ports of the graph's external nodes ([`nodes::external`]), in node order: the
    /// ROS 2 side (`ratelab::ros2::external`) connects them.
    pub external: Vec<Arc<ExternalPort>>,
    /// The nodes' faults: the settings' and those injected by command ([`faults`]).
    pub faults: Arc<faults::FaultBook>,
    /// The lines of the text log ([`ratelab_core::textlog`]) the graph's nodes wrote while
    /// [`Graph::build`] built them (a Python node's constructor's `get_logger()` lines and
    /// prints), on the building thread, oldest first, at most [`BUILD_LINES`] (the last
    /// ones): a ROS 2 offer started after the build puts them on each node's `/rosout`
    /// first, as a ROS 2 node's constructor's lines are its first. Empty in copies made
    /// while building (a step observer's).
    pub build_lines: Arc<[ratelab_core::textlog::LogLine]>,
}

/// The most lines [`GraphHandles::build_lines`] keeps: `/rosout`'s depth (rcl's, keep last
/// 1000).
pub const BUILD_LINES: usize = 1000;

/// Keep the lines written with a node's name on the calling thread (the graph's building)
/// from now until the returned recorder is dropped, the last [`BUILD_LINES`] of them.
fn record_build_lines() -> (
    Arc<Mutex<std::collections::VecDeque<ratelab_core::textlog::LogLine>>>,
    ratelab_core::textlog::Recorder,
) {
    let kept = Arc::new(Mutex::new(std::collections::VecDeque::new()));
    let keep = kept.clone();
    let builder = std::thread::current().id();
    let recorder = ratelab_core::textlog::add_recorder(Box::new(
        move |line: ratelab_core::textlog::LogLine| {
            if line.node.is_some() && std::thread::current().id() == builder {
                let mut kept = lock(&keep);
                if kept.len() == BUILD_LINES {
                    kept.pop_front();
                }
                kept.push_back(line);
            }
        },
    ));
    (kept, recorder)
}

/// Phase changes asked for and not yet taken: each node and its new phase offset
/// ([`GraphHandles::phase_request`]). Looking for none costs one atomic load.
#[derive(Debug, Default)]
pub struct PhaseRequests {
    pending: std::sync::atomic::AtomicBool,
    asked: Mutex<Vec<(NodeId, ratelab_core::time::Nanos)>>,
}

impl PhaseRequests {
    /// Ask for node `node`'s ticks to move to phase offset `phase`.
    pub fn push(&self, node: NodeId, phase: ratelab_core::time::Nanos) {
        lock(&self.asked).push((node, phase));
        self.pending
            .store(true, std::sync::atomic::Ordering::Release);
    }

    /// Take the changes asked for, oldest first (none: an empty list).
    pub fn take(&self) -> Vec<(NodeId, ratelab_core::time::Nanos)> {
        if !self
            .pending
            .swap(false, std::sync::atomic::Ordering::Acquire)
        {
            return Vec::new();
        }
        std::mem::take(&mut *lock(&self.asked))
    }

    /// The changes asked for and not yet taken (a capture's).
    pub fn save(&self) -> Vec<(NodeId, ratelab_core::time::Nanos)> {
        lock(&self.asked).clone()
    }

    /// Put back what [`PhaseRequests::save`] gave.
    pub fn load(&self, saved: &[(NodeId, ratelab_core::time::Nanos)]) {
        let mut asked = lock(&self.asked);
        asked.clear();
        asked.extend_from_slice(saved);
        (self.pending).store(!asked.is_empty(), std::sync::atomic::Ordering::Release);
    }
}

impl GraphHandles {
    /// Node `id`'s rate.
    pub fn rate(&self, id: NodeId) -> &Rate {
        &self.rates[id.0]
    }

    /// The chain policy's rate (the chapter's control rate); `None` when the graph has no
    /// chapter chain ([`Chain`]).
    pub fn control_rate(&self) -> Option<&Rate> {
        self.spec.chain.map(|c| self.rate(c.policy))
    }

    /// The chain sensor's rate; `None` when the graph has no chapter chain.
    pub fn sensor_rate(&self) -> Option<&Rate> {
        self.spec.chain.map(|c| self.rate(c.sensor))
    }

    /// What drives the actuator, as metrics and summaries name it: the brain's label when
    /// the chain's policy is a `policy` node, else the node's own code (a Python node's
    /// script and class, a Rust kind, a ROS 2 node); a graph without the chapter's chain
    /// says so.
    pub fn brain_label(&self) -> String {
        let Some(chain) = self.spec.chain else {
            return "none (the graph has no policy driving the actuator)".into();
        };
        let policy = self.spec.node(chain.policy);
        match policy.kind.code() {
            Code::Ros2 => format!("external ROS 2 node '{}'", policy.name),
            Code::Rust => format!("Rust node '{}' (kind {})", policy.name, policy.kind),
            Code::Python => match &policy.python {
                Some(p) => format!(
                    "Python node '{}' ({}{})",
                    policy.name,
                    p.script,
                    p.class
                        .as_ref()
                        .map(|c| format!(":{c}"))
                        .unwrap_or_default()
                ),
                None => format!("Python node '{}'", policy.name),
            },
            Code::BuiltIn if policy.kind.def().uses_brain => self.brain.label(),
            Code::BuiltIn => format!("node '{}' (kind {})", policy.name, policy.kind),
        }
    }

    /// Topic `id`.
    pub fn topic(&self, id: TopicId) -> &AnyTopic {
        &self.topics[id.0]
    }

    /// Every topic's counters as of their latest operations, by [`TopicId`].
    pub fn topic_stats(&self) -> TopicCounters {
        self.topics.iter().map(AnyTopic::stats).collect()
    }

    /// Every topic's counters at run time `now`, by [`TopicId`].
    pub fn topic_stats_at(&self, now: ratelab_core::time::Nanos) -> TopicCounters {
        self.topics.iter().map(|t| t.stats_at(now)).collect()
    }

    /// Every node's current rate, Hz, by [`NodeId`].
    pub fn rates_hz(&self) -> Vec<f64> {
        self.rates.iter().map(Rate::hz).collect()
    }

    /// Set every topic's history depth (the chapter's one queue depth).
    ///
    /// # Errors
    /// [`ZeroDepth`] for 0 (nothing changes).
    pub fn set_queue_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        if depth == 0 {
            return Err(ZeroDepth);
        }
        for t in &self.topics {
            t.set_depth(depth)?;
        }
        Ok(())
    }

    /// The graph's shape as it is now: the spec with the current rates and depths.
    pub fn current_spec(&self) -> GraphSpec {
        let mut spec = (*self.spec).clone();
        for (n, r) in spec.nodes.iter_mut().zip(&self.rates) {
            n.rate_hz = r.hz();
        }
        for (t, h) in spec.topics.iter_mut().zip(&self.topics) {
            t.depth = h.stats().depth;
            t.qos = h.qos();
        }
        for (n, l) in spec.nodes.iter_mut().zip(&self.liveliness) {
            n.liveliness_lease = l.lease();
        }
        if let Some(over) = *lock(&self.executor) {
            spec.set_executor(over);
        }
        spec
    }
}

/// A built graph: the nodes (in tie-break order) plus the handles.
pub struct Graph {
    /// The nodes, by [`NodeId`].
    pub nodes: Vec<GraphNode>,
    /// Handles into the running graph.
    pub handles: GraphHandles,
}

/// Why a graph cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// A rate out of range.
    #[error(transparent)]
    Rate(#[from] InvalidRate),
    /// Queue depth 0.
    #[error(transparent)]
    Depth(#[from] ZeroDepth),
    /// A node cannot be made: a Python node's script cannot be loaded (naming the file), a
    /// registered kind's maker refused the node's parameters (naming the node). One line.
    #[error("{0}")]
    Node(String),
}

/// Connect each subscription whose requested QoS its topic's QoS now meets, and leave
/// unconnected each one it does not ([`GraphSpec::incompatible`]: ROS 2's compatibility
/// rules): at the start of a run, and after a live change of a topic's QoS.
pub fn connect_subscriptions(spec: &GraphSpec, topics: &[AnyTopic]) {
    for (i, (t, topic)) in spec.topics.iter().zip(topics).enumerate() {
        if t.requested.is_empty() {
            continue;
        }
        let bad = spec.incompatible(TopicId(i), &topic.qos());
        // Each subscription's verdict by its index (hashed: a topic may have many).
        let verdict: std::collections::HashMap<usize, _> =
            bad.iter().map(|entry| (entry.0, entry)).collect();
        for (k, &n) in t.subscribers.iter().enumerate() {
            let queue = topic.subscription(k);
            let failed = verdict.get(&k).copied();
            let was = queue.matched();
            queue.set_matched(failed.is_none());
            // Said when it changes, as ROS 2 raises its event when the pair is discovered.
            let node = Some(spec.node(n).name.as_str());
            match failed {
                Some((.., m)) if was => ratelab_core::textlog::emit_for(
                    node,
                    None,
                    ratelab_core::textlog::Level::Warn,
                    &format!(
                        "incompatible QoS on {}: {}; it receives nothing",
                        t.name,
                        m.iter()
                            .map(ToString::to_string)
                            .collect::<Vec<_>>()
                            .join("; ")
                    ),
                ),
                None if !was => ratelab_core::textlog::emit_for(
                    node,
                    None,
                    ratelab_core::textlog::Level::Info,
                    &format!("QoS on {} now compatible: connected", t.name),
                ),
                _ => {}
            }
        }
    }
}

/// Each node's liveliness, its lease running from when it joins (t = 0, or its `start_ms`:
/// a node that joins late is not missed before it exists).
fn liveliness_of(spec: &GraphSpec) -> Vec<Arc<Liveliness>> {
    spec.nodes
        .iter()
        .map(|n| {
            let l = Liveliness::new(n.liveliness_lease);
            if let Some(at) = n.start {
                l.starts_at(at);
            }
            Arc::new(l)
        })
        .collect()
}

/// A node that joins late (`start_ms`) has subscriptions that come into being with it
/// ([`AnyTopic::set_joins_at`]) and publishers that owe no deadline before it
/// ([`AnyTopic::set_publisher_start`]).
fn start_late_nodes(spec: &GraphSpec, topics: &[AnyTopic]) {
    for (t, topic) in spec.topics.iter().zip(topics) {
        if let Some(at) = spec.node(t.publisher).start {
            topic.set_publisher_start(at);
        }
        for (k, &n) in t.subscribers.iter().enumerate() {
            if let Some(at) = spec.node(n).start {
                topic.subscription(k).set_joins_at(at);
            }
        }
    }
}

impl Graph {
    /// Build `spec` around `plant` (already reset). Every policy node runs `brain`; sensor
    /// noise and links are seeded from `seed`. `observers` are told about every actuator
    /// tick; `keep_trace` keeps every step record. `faults` name nodes by name (unknown
    /// names are ignored here; [`crate::RunConfig::validate`] refuses them).
    ///
    /// # Errors
    /// [`GraphError`] for a bad rate or a zero depth (a validated spec has neither), or a
    /// Python node whose script cannot be loaded.
    pub fn build(
        spec: &GraphSpec,
        plant: CartPole,
        brain: BrainSlot,
        seed: u64,
        keep_trace: bool,
        mut observers: Vec<Box<dyn StepObserver>>,
        faults: &[Fault],
    ) -> Result<Graph, GraphError> {
        let plant = Arc::new(Mutex::new(plant));
        let topics = spec
            .topics
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let link_seed = seed.rotate_left(16) ^ (i as u64 + 1);
                AnyTopic::with_subscriptions(
                    &t.name,
                    t.msg,
                    t.depth,
                    t.qos,
                    link_seed,
                    t.subscribers.len(),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        connect_subscriptions(spec, &topics);
        start_late_nodes(spec, &topics);
        let liveliness = liveliness_of(spec);
        let rates = spec
            .nodes
            .iter()
            .map(|n| Rate::new(n.rate_hz))
            .collect::<Result<Vec<_>, _>>()?;
        let log = Arc::new(Mutex::new(RunLog::new(keep_trace)));
        let external: Vec<Arc<ExternalPort>> = spec
            .nodes
            .iter()
            .enumerate()
            .filter_map(|(i, n)| {
                let settings = n.external()?;
                let output = *n.publishes.first()?;
                let largest = spec
                    .topic(output)
                    .msg
                    .ros2()
                    .map_or(ratelab_core::limits::MAX_ROS_MESSAGE_BYTES, |c| c.max_bytes);
                Some(Arc::new(ExternalPort::new(
                    NodeId(i),
                    &n.name,
                    n.subscribes.first().copied(),
                    (output, largest),
                    settings,
                )))
            })
            .collect();
        let id_of = |n: &str| spec.node_id(n);
        let faults = Arc::new(faults::FaultBook::new(spec.nodes.len(), faults, id_of));
        let handles = GraphHandles {
            faults: faults.clone(),
            spec: Arc::new(spec.clone()),
            rates: rates.clone(),
            topics: topics.clone(),
            brain: brain.clone(),
            plant: plant.clone(),
            log: log.clone(),
            liveliness: liveliness.clone(),
            external: external.clone(),
            executor: Arc::default(),
            plan_request: Arc::default(),
            phase_request: Arc::default(),
            build_lines: Arc::from(Vec::new()),
        };
        let (built, recorder) = record_build_lines();
        for o in &mut observers {
            o.attach(&handles);
        }
        let mut observers: Option<Vec<Box<dyn StepSink>>> = Some(
            observers
                .into_iter()
                .map(|o| Box::new(Observer(o)) as Box<dyn StepSink>)
                .collect(),
        );
        let nodes = (0..spec.nodes.len())
            .map(|i| build_node(&handles, seed, i, &mut observers))
            .collect::<Result<Vec<_>, _>>()?;
        drop(recorder);
        let mut handles = handles;
        handles.build_lines = Arc::from(Vec::from(std::mem::take(&mut *lock(&built))));
        Ok(Graph { nodes, handles })
    }

    /// Node `i` of the graph `handles` hold built afresh, as [`Graph::build`] built it (its
    /// kind's code and parameters as `handles.spec` gives them now, its state new), on the
    /// graph's topics, rate, liveliness and faults: a node restarted in place in a running
    /// graph (`ratelab::runcore::RunCore::restart_nodes`). It tells no step observers (the
    /// graph's stay with the node that had them).
    ///
    /// # Errors
    /// [`GraphError`] for a node whose code cannot be loaded (a Python script that no
    /// longer loads), or an index past the graph's nodes.
    pub fn rebuild_node(
        handles: &GraphHandles,
        seed: u64,
        i: usize,
    ) -> Result<GraphNode, GraphError> {
        if i >= handles.spec.nodes.len() {
            return Err(GraphError::Node(format!("no node {i} in the graph")));
        }
        build_node(handles, seed, i, &mut None)
    }
}

/// Node `i` of `handles.spec`, on the graph's topics, rates, liveliness, faults, plant,
/// brain and log; the actuator takes `observers` ([`Graph::build`]).
fn build_node(
    handles: &GraphHandles,
    seed: u64,
    i: usize,
    observers: &mut Option<Vec<Box<dyn StepSink>>>,
) -> Result<GraphNode, GraphError> {
    let spec = &handles.spec;
    let topics = &handles.topics;
    let n = &spec.nodes[i];
    let outbox = Outbox::new();
    let core = NodeCore {
        name: n.name.clone(),
        id: NodeId(i),
        rate: handles.rates[i].clone(),
        liveliness: handles.liveliness[i].clone(),
        faults: handles.faults.clone(),
        outbox: outbox.clone(),
        compute: n.compute.map(|c| ComputeDraw::new(c, seed, i)),
    };
    // Its topics, in the graph file's order: what it reads, its own subscription's queue
    // (a topic of several subscribers has one per subscriber).
    let inputs: Vec<AnyTopic> = n
        .subscribes
        .iter()
        .map(|t| {
            let subs = &spec.topic(*t).subscribers;
            // Subscribers are sorted (`GraphSpec`'s build).
            match subs.binary_search(&NodeId(i)).ok() {
                Some(k) if subs.len() > 1 => topics[t.0].subscription(k),
                _ => topics[t.0].clone(),
            }
        })
        .collect();
    let outputs: Vec<AnyTopic> = n.publishes.iter().map(|t| topics[t.0].clone()).collect();
    // The external ports are in node order: found by a binary search, not a scan per node.
    let attachment = handles
        .external
        .binary_search_by_key(&i, |p| p.node.0)
        .ok()
        .map(|k| handles.external[k].clone() as Arc<dyn std::any::Any + Send + Sync>);
    let mut cx = BuildContext {
        node: NodeContext {
            name: &n.name,
            id: NodeId(i),
            period: handles.rates[i].period(),
            seed,
            params: &n.params,
            inputs: &inputs,
            outputs: &outputs,
        },
        run: RunParts {
            plant: &handles.plant,
            brain: &handles.brain,
            log: &handles.log,
            topics,
            action: spec.chain.map(|c| &topics[c.action.0]),
            estimate: spec.estimate_topic().zip(spec.chain).map(|(t, c)| {
                // The policy's own queue of it, when the topic has several subscribers.
                let subs = &spec.topic(t).subscribers;
                match subs.binary_search(&c.policy).ok() {
                    Some(k) if subs.len() > 1 => topics[t.0].subscription(k),
                    _ => topics[t.0].clone(),
                }
            }),
            observers,
        },
        adapter: AdapterParts {
            python: n.python.as_ref(),
            rate: &handles.rates[i],
            liveliness: &handles.liveliness[i],
            attachment,
        },
        outbox: &outbox,
    };
    let work = (n.kind.def().make)(&mut cx).map_err(GraphError::Node)?;
    Ok(GraphNode::new(core, work))
}
