//! The graph as a recording draws it: lists of nodes and topics.
//!
//! Everything the recording derives from the graph (the node graph, the `bus/<topic>/…`
//! entities, the blueprint's per-topic and per-node series) comes from a [`GraphShape`],
//! which is built in one place, [`GraphShape::from_handles`].

use ratelab_core::msg::ForceMsg;
use ratelab_core::qos::{Liveliness, TopicQos};
use ratelab_core::rate::Rate;
use ratelab_core::topic::{Subscription, TopicStats};
use ratelab_runtime::graph::GraphHandles;
use std::collections::BTreeMap;
use std::sync::Arc;

/// One node of the graph as the recording draws it.
#[derive(Clone, Debug)]
pub struct NodeShape {
    /// The node's name (as in `nodes/<name>/lateness_ms`).
    pub name: String,
    /// Its rate, read live (a lab session changes it mid-run).
    pub rate: Rate,
    /// Its liveliness, read live (`None` when not known: nothing about it is recorded).
    pub liveliness: Option<Arc<Liveliness>>,
    /// The OS process it runs in, for a graph across processes (`None` in one process).
    pub process: Option<String>,
    /// A learner's Python node (`kind = "python"`): its graph label says so.
    pub python: bool,
}

impl NodeShape {
    /// Its liveliness lease now, if it has one.
    pub(crate) fn lease(&self) -> Option<ratelab_core::time::Nanos> {
        self.liveliness.as_ref().and_then(|l| l.lease())
    }

    /// Its label in the node graph: `policy · 50 Hz`, then `python` for a Python node and,
    /// across processes, `process <name>`, a line each.
    pub(crate) fn label(&self) -> String {
        let mut lines = vec![format!(
            "{} · {} Hz",
            self.name,
            super::hz_label(self.rate.hz())
        )];
        if self.python {
            lines.push("python".to_string());
        }
        if let Some(p) = &self.process {
            lines.push(format!("process {p}"));
        }
        lines.join("\n")
    }
}

/// One topic of the graph as the recording draws it.
#[derive(Clone)]
pub struct TopicShape {
    /// The topic's name, `/obs`-style.
    pub name: String,
    /// The node that publishes on it.
    pub publisher: String,
    /// The nodes that read it.
    pub subscribers: Vec<String>,
    /// Its counters and depth, read live.
    pub stats: Arc<dyn Fn() -> TopicStats + Send + Sync>,
    /// Its QoS (apart from the depth) as the run started.
    pub qos: TopicQos,
    /// Its QoS, read live (a lab session changes it mid-run).
    pub live_qos: Arc<dyn Fn() -> TopicQos + Send + Sync>,
}

impl TopicShape {
    /// The entity path part of the topic: its name without the leading `/`.
    pub(crate) fn entity(&self) -> String {
        super::bus_name(&self.name)
    }

    /// Its label in the node graph, with its depth now: `/obs · depth 1`. A topic with QoS
    /// beyond the depth shows it in short, a part a line under its name (`dl 30 ms zero`,
    /// `link 20%`), so the label stays about as wide as its neighbours (one line of every
    /// part made the graph's text tiny and the label covered its arrows); the chapter's
    /// keep-last/latest rule goes without saying (the depth is on the first line).
    pub(crate) fn label(&self) -> String {
        let depth = (self.stats)().depth;
        let first = format!("{} · depth {depth}", self.name);
        match Some((self.live_qos)()).filter(|q| !q.is_default()) {
            Some(q) => {
                let mut lines = vec![first];
                lines.extend(
                    q.short_parts(depth)
                        .into_iter()
                        .filter(|p| !(p.starts_with("KL") && p.ends_with(" latest"))),
                );
                lines.join("\n")
            }
            None => first,
        }
    }
}

/// What a lab session can change in a running graph, as last seen: each node's rate, each
/// topic's depth and QoS.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct GraphState {
    pub(crate) rates: Vec<f64>,
    pub(crate) depths: Vec<usize>,
    pub(crate) qos: Vec<TopicQos>,
}

/// The graph as the recording needs it: lists of nodes and topics (built in one place,
/// [`GraphShape::from_handles`]), from which the node graph, the `bus/<topic>/…` entities and
/// the blueprint's per-topic and per-node series are all derived.
#[derive(Clone, Default)]
pub struct GraphShape {
    /// The nodes, in the executor's order.
    pub nodes: Vec<NodeShape>,
    /// The topics.
    pub topics: Vec<TopicShape>,
    /// The node whose period is the control period (the latency plot's reference line).
    pub controller: Option<String>,
    /// The topic the policy publishes its force on: each message on it is logged as a
    /// published action (the actuator applies it, or a safety node's version of it).
    pub commands: Option<Arc<Subscription<ForceMsg>>>,
}

impl GraphShape {
    /// The shape of a running graph, from its spec and handles: every node with its live
    /// rate, every topic with its publisher, subscriber and live counters; the chain's
    /// policy sets the control period, and its output topic is the published force.
    pub fn from_handles(h: &GraphHandles) -> Self {
        let commands = h.spec.chain.and_then(|c| {
            h.topic(c.action)
                .subscription(0)
                .typed::<ForceMsg>()
                .cloned()
        });
        Self::build(
            &h.spec,
            &h.rates,
            &h.liveliness,
            |i| {
                let topic = h.topics[i].clone();
                Arc::new(move || topic.stats())
            },
            |i| {
                let topic = h.topics[i].clone();
                Arc::new(move || topic.qos())
            },
            commands,
        )
    }

    /// The shape of a graph that runs elsewhere (in other processes), as data: each node at
    /// its rate in `spec` (no liveliness) in its process (`spec`'s placement), each topic's counters read from `stats` (by
    /// [`ratelab_runtime::graph::TopicId`]; zeros for a topic it lacks), its QoS as `spec` has it, and
    /// the published force read from `commands`.
    pub fn from_spec(
        spec: &ratelab_runtime::graph::GraphSpec,
        stats: Arc<std::sync::Mutex<Vec<TopicStats>>>,
        commands: Option<Arc<Subscription<ForceMsg>>>,
    ) -> Result<Self, ratelab_core::rate::InvalidRate> {
        let rates = spec
            .nodes
            .iter()
            .map(|n| Rate::new(n.rate_hz))
            .collect::<Result<Vec<_>, _>>()?;
        let mut shape = Self::build(
            spec,
            &rates,
            &[],
            |i| {
                let stats = stats.clone();
                Arc::new(move || {
                    ratelab_runtime::graph::lock(&stats)
                        .get(i)
                        .copied()
                        .unwrap_or_default()
                })
            },
            |i| {
                let qos = spec.topics[i].qos;
                Arc::new(move || qos)
            },
            commands,
        );
        for (i, n) in shape.nodes.iter_mut().enumerate() {
            n.process = Some(spec.process_of(ratelab_runtime::graph::NodeId(i)));
        }
        Ok(shape)
    }

    /// The one place the shape is put together: nodes with `rates` (and `liveliness`,
    /// where known), topics with the readers `stats(i)` and `live_qos(i)`.
    fn build(
        spec: &ratelab_runtime::graph::GraphSpec,
        rates: &[Rate],
        liveliness: &[Arc<Liveliness>],
        stats: impl Fn(usize) -> Arc<dyn Fn() -> TopicStats + Send + Sync>,
        live_qos: impl Fn(usize) -> Arc<dyn Fn() -> TopicQos + Send + Sync>,
        commands: Option<Arc<Subscription<ForceMsg>>>,
    ) -> Self {
        Self {
            nodes: spec
                .nodes
                .iter()
                .zip(rates)
                .enumerate()
                .map(|(i, (n, rate))| NodeShape {
                    name: n.name.clone(),
                    rate: rate.clone(),
                    liveliness: liveliness.get(i).cloned(),
                    process: None,
                    python: n.python.is_some(),
                })
                .collect(),
            topics: spec
                .topics
                .iter()
                .enumerate()
                .map(|(i, t)| TopicShape {
                    name: t.name.clone(),
                    publisher: spec.node(t.publisher).name.clone(),
                    subscribers: t
                        .subscribers
                        .iter()
                        .map(|s| spec.node(*s).name.clone())
                        .collect(),
                    stats: stats(i),
                    qos: t.qos,
                    live_qos: live_qos(i),
                })
                .collect(),
            controller: spec.chain.map(|c| spec.node(c.policy).name.clone()),
            commands,
        }
    }

    /// Left-to-right columns for the node graph: sources in column 0, each topic one column
    /// right of its publisher, each subscriber one right of the topic (longest path; a cycle
    /// stops growing after as many rounds as there are vertices). Returns (id, column) for
    /// nodes then topics.
    pub(crate) fn columns(&self) -> Vec<(String, usize)> {
        let mut col: BTreeMap<String, usize> = BTreeMap::new();
        for n in &self.nodes {
            col.insert(n.name.clone(), 0);
        }
        for t in &self.topics {
            col.insert(t.name.clone(), 1);
        }
        for _ in 0..(self.nodes.len() + self.topics.len()) {
            let mut changed = false;
            for t in &self.topics {
                let from = col.get(&t.publisher).copied().unwrap_or(0) + 1;
                if from > col[&t.name] {
                    col.insert(t.name.clone(), from);
                    changed = true;
                }
                for s in &t.subscribers {
                    let to = col[&t.name] + 1;
                    if col.get(s).is_some_and(|c| to > *c) {
                        col.insert(s.clone(), to);
                        changed = true;
                    }
                }
            }
            if !changed {
                break;
            }
        }
        self.nodes
            .iter()
            .map(|n| n.name.clone())
            .chain(self.topics.iter().map(|t| t.name.clone()))
            .map(|id| {
                let c = col[&id];
                (id, c)
            })
            .collect()
    }

    /// Rates, depths and QoS now, to notice a change.
    pub(crate) fn state(&self) -> GraphState {
        GraphState {
            rates: self.nodes.iter().map(|n| n.rate.hz()).collect(),
            depths: self.topics.iter().map(|t| (t.stats)().depth).collect(),
            qos: self.topics.iter().map(|t| (t.live_qos)()).collect(),
        }
    }

    pub(crate) fn controller_period_ms(&self) -> Option<f64> {
        let name = self.controller.as_ref()?;
        let node = self.nodes.iter().find(|n| &n.name == name)?;
        Some(node.rate.period().as_millis_f64())
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::graph_positions;

    /// A shape with `topics` (name, publisher, subscribers) and `nodes` at 50 Hz; the second
    /// node is the controller.
    pub(crate) fn shape(topics: &[(&str, &str, &[&str])], nodes: &[&str]) -> GraphShape {
        GraphShape {
            nodes: nodes
                .iter()
                .map(|n| NodeShape {
                    name: n.to_string(),
                    rate: Rate::new(50.0).unwrap(),
                    liveliness: None,
                    process: None,
                    python: false,
                })
                .collect(),
            topics: topics
                .iter()
                .map(|(name, publisher, subs)| TopicShape {
                    name: name.to_string(),
                    publisher: publisher.to_string(),
                    subscribers: subs.iter().map(|s| s.to_string()).collect(),
                    stats: Arc::new(TopicStats::default),
                    qos: TopicQos::default(),
                    live_qos: Arc::new(TopicQos::default),
                })
                .collect(),
            controller: Some(nodes[1].to_string()),
            commands: None,
        }
    }

    #[test]
    fn the_graph_reads_left_to_right_whatever_the_list_order() {
        // Listed out of order on purpose: columns follow publisher → topic → subscriber.
        let s = shape(
            &[
                ("/action", "policy", &["actuator"]),
                ("/obs", "sensor", &["policy", "logger"]),
            ],
            &["actuator", "policy", "sensor", "logger"],
        );
        let cols: BTreeMap<String, usize> = s.columns().into_iter().collect();
        assert_eq!(cols["sensor"], 0);
        assert_eq!(cols["/obs"], 1);
        assert_eq!(cols["policy"], 2);
        assert_eq!(cols["logger"], 2);
        assert_eq!(cols["/action"], 3);
        assert_eq!(cols["actuator"], 4);
        // Two nodes in one column are stacked, not overlapped.
        let (positions, _) = graph_positions(&s);
        let at: BTreeMap<String, [f32; 2]> = positions.into_iter().collect();
        assert_eq!(at["policy"][0], at["logger"][0]);
        assert_ne!(at["policy"][1], at["logger"][1]);
        assert!(at["sensor"][0] < at["/obs"][0] && at["/action"][0] < at["actuator"][0]);
    }

    #[test]
    fn a_cycle_does_not_hang_the_layout() {
        let s = shape(&[("/a", "x", &["y"]), ("/b", "y", &["x"])], &["x", "y"]);
        assert_eq!(s.columns().len(), 4);
    }
}
