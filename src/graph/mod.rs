//! The graph: nodes at fixed rates exchanging messages on topics, around one cartpole.
//!
//! Its shape is data: a [`GraphSpec`] read from a graph file ([`spec`]; the chapter's
//! sensor → `/obs` → policy → `/action` → actuator is `graphs/cartpole.toml`, the default).
//! [`Graph::build`] turns a spec into runnable nodes ([`nodes`]) and the [`GraphHandles`]
//! every view uses (rates, topics, brain, plant, the run log), all indexed by the spec's
//! [`NodeId`]/[`TopicId`].

pub mod estimator;
pub mod nodes;
pub mod registry;
pub mod spec;

use crate::executor::ComputeDraw;
use crate::msg::AnyTopic;
use crate::node::Node;
use crate::plant::CartPole;
use crate::policy::BrainSlot;
use crate::publisher::{Outbox, Publisher};
use crate::qos::{Fault, Liveliness};
use crate::rate::{InvalidRate, Rate};
use crate::runlog::{RunLog, StepRecord, TopicCounters};
use crate::topic::ZeroDepth;
use nodes::{
    Actuator, Estimator, External, ExternalPort, GraphNode, NodeCore, PolicyNode, Safety, Sensor,
    SensorNoise, SensorOutput, Work,
};
pub use spec::{Chain, GraphSpec, MsgType, NodeId, NodeKind, TopicId};
use std::sync::{Arc, Mutex, MutexGuard};

/// The plant shared by the sensors (read) and the actuator (steps).
pub type SharedPlant = Arc<Mutex<CartPole>>;

/// Lock a shared value, tolerating poison (each holder leaves it consistent).
pub fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Something told about every actuator tick (a recorder, the lab's telemetry).
/// Called on the actuator's thread: it must not block.
pub trait StepObserver: Send {
    /// The graph was built: a chance to keep handles (rates, topics) for later ticks.
    fn attach(&mut self, _handles: &GraphHandles) {}
    /// One actuator tick happened.
    fn on_step(&mut self, rec: &StepRecord);
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
    /// The ports of the graph's external nodes ([`nodes::external`]), in node order: the
    /// ROS 2 side ([`crate::ros2::external`]) connects them.
    pub external: Vec<Arc<ExternalPort>>,
}

impl GraphHandles {
    /// Node `id`'s rate.
    pub fn rate(&self, id: NodeId) -> &Rate {
        &self.rates[id.0]
    }

    /// The chain policy's rate (the chapter's control rate).
    pub fn control_rate(&self) -> &Rate {
        self.rate(self.spec.chain.policy)
    }

    /// The chain sensor's rate.
    pub fn sensor_rate(&self) -> &Rate {
        self.rate(self.spec.chain.sensor)
    }

    /// What drives the chain's policy, as metrics and summaries name it: the brain's label,
    /// or, when the policy is a Python node, that node's script and class; an external
    /// node says so.
    pub fn brain_label(&self) -> String {
        let policy = self.spec.node(self.spec.chain.policy);
        if policy.kind == NodeKind::External {
            return format!("external ROS 2 node '{}'", policy.name);
        }
        match &policy.python {
            Some(p) => format!(
                "Python node '{}' ({}{})",
                policy.name,
                p.script,
                p.class
                    .as_ref()
                    .map(|c| format!(":{c}"))
                    .unwrap_or_default()
            ),
            None => self.brain.label(),
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
    pub fn topic_stats_at(&self, now: crate::time::Nanos) -> TopicCounters {
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
        spec
    }
}

/// A built graph: the nodes (in tie-break order) plus the handles.
pub struct Graph {
    /// The nodes, by [`NodeId`].
    pub nodes: Vec<Box<dyn Node>>,
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
    /// A Python node's script cannot be loaded (one line, naming the file).
    #[error(transparent)]
    Python(#[from] crate::python::PythonError),
    /// A node of a registered kind cannot be made: the kind is not registered in this
    /// process, or its maker refused the node's parameters (one line, naming the node).
    #[error("{0}")]
    Registered(String),
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
                AnyTopic::with_qos(&t.name, t.msg, t.depth, t.qos, link_seed)
            })
            .collect::<Result<Vec<_>, _>>()?;
        let liveliness: Vec<Arc<Liveliness>> = spec
            .nodes
            .iter()
            .map(|n| Arc::new(Liveliness::new(n.liveliness_lease)))
            .collect();
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
                let settings = n.external?;
                let output = *n.publishes.first()?;
                Some(Arc::new(ExternalPort::new(
                    NodeId(i),
                    &n.name,
                    n.subscribes.first().copied(),
                    output,
                    settings,
                )))
            })
            .collect();
        let handles = GraphHandles {
            spec: Arc::new(spec.clone()),
            rates: rates.clone(),
            topics: topics.clone(),
            brain: brain.clone(),
            plant: plant.clone(),
            log: log.clone(),
            liveliness: liveliness.clone(),
            external: external.clone(),
        };
        for o in &mut observers {
            o.attach(&handles);
        }
        let mut observers = Some(observers);
        let nodes = spec
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| -> Result<Box<dyn Node>, GraphError> {
                let outbox = Outbox::new();
                let core = NodeCore {
                    name: n.name.clone(),
                    id: NodeId(i),
                    rate: rates[i].clone(),
                    liveliness: liveliness[i].clone(),
                    faults: faults
                        .iter()
                        .filter(|f| f.node == n.name)
                        .cloned()
                        .collect(),
                    outbox: outbox.clone(),
                    compute: n.compute.map(|c| ComputeDraw::new(c, seed, i)),
                };
                // Every other kind reads and publishes at most one topic each.
                let input = n.subscribes.first().map(|t| &topics[t.0]);
                let output = n.publishes.first().map(|t| &topics[t.0]);
                // A python or registered node's topics, in the graph file's order.
                let of = |ts: &[TopicId]| -> Vec<AnyTopic> {
                    ts.iter().map(|t| topics[t.0].clone()).collect()
                };
                let work = match (n.kind, (input, output)) {
                    (NodeKind::Sensor, (_, Some(out))) => {
                        let p = &n.params;
                        Work::Sensor(Sensor {
                            plant: plant.clone(),
                            output: match out {
                                AnyTopic::State(t) => {
                                    SensorOutput::State(Publisher::new(t.clone(), outbox.clone()))
                                }
                                AnyTopic::Position(t) => SensorOutput::Position(Publisher::new(
                                    t.clone(),
                                    outbox.clone(),
                                )),
                                AnyTopic::Force(_) => {
                                    unreachable!("validated: a sensor publishes state or position")
                                }
                            },
                            noise: (p.noise_pos_m > 0.0 || p.noise_angle_rad > 0.0).then(|| {
                                SensorNoise::new(seed, NodeId(i), p.noise_pos_m, p.noise_angle_rad)
                            }),
                        })
                    }
                    (
                        NodeKind::Estimator,
                        (Some(AnyTopic::Position(i)), Some(AnyTopic::State(o))),
                    ) => Work::Estimator(Estimator {
                        input: i.clone(),
                        output: Publisher::new(o.clone(), outbox.clone()),
                        filter: estimator::VelocityFilter::new(n.params.cutoff_hz),
                        last_seq: None,
                        origin: None,
                    }),
                    (NodeKind::Policy, (Some(AnyTopic::State(i)), Some(AnyTopic::Force(o)))) => {
                        Work::Policy(PolicyNode {
                            brain: brain.clone(),
                            input: i.clone(),
                            output: Publisher::new(o.clone(), outbox.clone()),
                        })
                    }
                    (NodeKind::Safety, (Some(AnyTopic::Force(i)), Some(AnyTopic::Force(o)))) => {
                        Work::Safety(Safety {
                            input: i.clone(),
                            output: Publisher::new(o.clone(), outbox.clone()),
                            max_force_n: n.params.max_force_n,
                        })
                    }
                    (NodeKind::Python, _) => {
                        let python = n
                            .python
                            .as_ref()
                            .expect("validated: a python node's script");
                        Work::Python(Box::new(crate::python::node::PythonNode::load(
                            &n.name,
                            python,
                            rates[i].period(),
                            of(&n.subscribes),
                            of(&n.publishes),
                            outbox.clone(),
                            seed,
                        )?))
                    }
                    (NodeKind::Registered, _) => {
                        let r = n
                            .registered
                            .as_ref()
                            .expect("validated: a registered node's kind");
                        let cx = registry::NodeContext {
                            name: &n.name,
                            period: rates[i].period(),
                            seed,
                            params: &r.params,
                        };
                        Work::Registered(
                            registry::make(
                                &r.kind,
                                &cx,
                                &of(&n.subscribes),
                                &of(&n.publishes),
                                &outbox,
                            )
                            .map_err(GraphError::Registered)?,
                        )
                    }
                    (NodeKind::External, (input, Some(output))) => {
                        let port = external
                            .iter()
                            .find(|p| p.node.0 == i)
                            .expect("made above for every external node")
                            .clone();
                        Work::External(Box::new(External {
                            port,
                            input: input.cloned(),
                            output: output.clone(),
                            outbox: outbox.clone(),
                            liveliness: liveliness[i].clone(),
                            origin: None,
                        }))
                    }
                    (NodeKind::Actuator, (Some(AnyTopic::Force(i)), None)) => {
                        Work::Actuator(Box::new(Actuator {
                            plant: plant.clone(),
                            input: i.clone(),
                            topics: topics.clone(),
                            log: log.clone(),
                            observers: observers.take().unwrap_or_default(),
                            held: None,
                            policy_output: match &topics[spec.chain.action.0] {
                                AnyTopic::Force(t) => Some(t.clone()),
                                _ => None,
                            },
                            reported: None,
                        }))
                    }
                    _ => unreachable!(
                        "validated spec: node '{}' is wired as its kind requires",
                        n.name
                    ),
                };
                Ok(Box::new(GraphNode::new(core, work)) as Box<dyn Node>)
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Graph { nodes, handles })
    }
}
