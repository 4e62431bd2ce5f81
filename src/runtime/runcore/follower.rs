//! Following a run's order of events without running its ticks: what the launcher of a
//! graph across processes does under the virtual clock (`ratelab::distributed`), where
//! every tick runs in its node's process and reports back. The order is the run core's
//! ([`super::RunCore::next_event`]): the same scheduler, the same instants, the same
//! executors' rules; only the ticks are elsewhere.

use crate::config::RunConfig;
use crate::graph::nodes::GraphNode;
use crate::scheduler::{Event, VirtualScheduler};
use ratelab_core::ids::NodeId;
use ratelab_core::rate::{InvalidRate, Rate};
use ratelab_core::time::Nanos;

/// A run's order of events, its ticks run elsewhere (module docs).
pub struct Follower {
    nodes: Vec<GraphNode>,
    sched: VirtualScheduler,
    duration: Nanos,
}

impl Follower {
    /// Follow the run of `cfg`'s graph: its nodes' rates and phase offsets, its executors,
    /// its duration. Commands are not followed (a run across processes takes none).
    ///
    /// # Errors
    /// [`InvalidRate`] for a node rate a graph file should not have let through.
    pub fn new(cfg: &RunConfig) -> Result<Self, InvalidRate> {
        let spec = &cfg.graph;
        let nodes = spec
            .nodes
            .iter()
            .enumerate()
            .map(|(i, n)| {
                // A stand-in: it never ticks here, every tick runs elsewhere.
                Ok(GraphNode::idle(&n.name, NodeId(i), Rate::new(n.rate_hz)?))
            })
            .collect::<Result<Vec<_>, InvalidRate>>()?;
        let sched = VirtualScheduler::with_plan(
            &nodes,
            &cfg.first_deadlines(),
            spec.execution_plan(),
            false,
        );
        Ok(Follower {
            nodes,
            sched,
            duration: cfg.duration,
        })
    }

    /// The run's next event, as [`super::RunCore::next_event`] draws it; `None` past the
    /// run's duration. Each is then taken with [`Follower::ran_elsewhere`].
    pub fn next_event(&mut self) -> Option<Event> {
        loop {
            if let Some(e) = self.sched.next_in_instant() {
                return Some(e);
            }
            let due = self.sched.next_due().filter(|&t| t <= self.duration)?;
            self.sched.begin_instant(due);
        }
    }

    /// `event` ran in its node's process, a start's tick computing for `compute` there
    /// ([`super::RunCore::ran_elsewhere`]).
    pub fn ran_elsewhere(&mut self, event: Event, compute: Nanos) {
        if let Event::Start { node, .. } = event {
            self.sched.start_elsewhere(&self.nodes, node, compute);
        }
    }

    /// The newest instant drawn (0 before any).
    pub fn now(&self) -> Nanos {
        self.sched.now()
    }

    /// The shortest period of the graph's nodes (1 ns for a graph of none).
    pub fn shortest_period(&self) -> Nanos {
        self.nodes
            .iter()
            .map(|n| n.rate().period())
            .min()
            .unwrap_or(Nanos(1))
    }

    /// The most ticks the graph's nodes start within any `span` of run time: each node's
    /// span over its period, rounded up, plus one (a tick at each end).
    pub fn ticks_within(&self, span: Nanos) -> u64 {
        self.nodes
            .iter()
            .map(|n| span.0 / n.rate().period().0.max(1) + 1)
            .fold(0u64, u64::saturating_add)
    }
}
