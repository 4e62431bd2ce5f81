//! The node kinds ratelab has built in, one file each — [`sensor`], [`camera`] (with
//! [`frame`], where a frame shows the world, and [`camera_render`], MuJoCo's offscreen
//! render it may use),
//! [`estimator`], [`image_estimator`], [`policy`], [`safety`], [`actuator`], [`python`] (a learner's script, run by
//! `ratelab::python::node`) and [`external`] (a ROS 2 node's proxy) — each its one
//! definition ([`crate::graph::kind::KindDef`]: ports, plant, parameters, `make`) and its
//! node, a [`ratelab_core::ports::RustNode`] like any program's (the Python node and the
//! proxy are adapters whose topics are any, [`ratelab_core::ports::AnyPorts`]).
//! [`super::registry`] registers them; a kind written outside ratelab is registered the
//! same way ([`super::registry::register`]).
//!
//! A **python** node runs its subscription callbacks for what arrived, then its timers; any
//! other kind its `tick`, given per input what its slot delivers (a new message, or every
//! tick's read with [`ratelab_core::ports::Held`]); what either published goes out with the
//! oldest origin among its inputs' newest messages (either may have several inputs and
//! outputs; the built-in kinds have at most one of each).
//!
//! Every node that publishes passes on the origin stamp of the message it derived its output
//! from (of several inputs, the oldest), so the actuator measures sense→act latency
//! (`now − origin`) across any chain.
//!
//! **Adding a built-in kind** is a file here (its `def()` and its `RustNode`) and its line
//! in [`super::registry`]'s list.

pub mod actuator;
pub mod camera;
pub mod camera_render;
pub mod estimator;
pub mod external;
pub mod frame;
pub mod image_estimator;
pub mod policy;
pub mod python;
pub mod safety;
pub mod sensor;

pub use external::{ExternalNodeSpec, ExternalPort};

use crate::graph::kind::NodeOf;
use ratelab_core::executor::ComputeDraw;
use ratelab_core::ids::NodeId;
use ratelab_core::node::{Flow, NodeState};
use ratelab_core::publisher::Outbox;
use ratelab_core::qos::Liveliness;
use ratelab_core::rate::Rate;
use ratelab_core::time::Nanos;
use std::sync::Arc;

/// What every node carries: its identity, tie-break rank and rate.
pub struct NodeCore {
    /// Its name (from the graph file).
    pub name: String,
    /// Its index in the graph (the tie-break rank).
    pub id: NodeId,
    /// Its rate (shared with the graph's handles).
    pub rate: Rate,
    /// Its liveliness, asserted by every tick (shared with the graph's handles).
    pub liveliness: Arc<Liveliness>,
    /// The graph's faults (`--stall`, `--kill`, and those injected by command): its ticks
    /// look up their own.
    pub faults: Arc<crate::graph::faults::FaultBook>,
    /// Its publishers' outbox (held during a tick with a compute time).
    pub outbox: Outbox,
    /// Its compute time's draws; `None`: its ticks take no time.
    pub compute: Option<ComputeDraw>,
}

/// A node of the graph: its kind's node (a [`ratelab_core::ports::RustNode`] bound to its
/// topics, [`NodeOf`]) around its [`NodeCore`]. What a scheduler runs (virtual or real,
/// `crate::scheduler`): it calls [`GraphNode::tick`] at the node's rate, on the thread its
/// executor gives it ([`ratelab_core::executor`]); a tick with a compute time publishes at
/// its end ([`GraphNode::hold_outputs`], [`GraphNode::publish_held`]). The rank breaks ties
/// between nodes due at the same instant: lower first, so the chapter's sensor (0) → policy
/// (1) → actuator (2) samples, thinks, then acts.
///
/// A node may also give its state at an instant ([`GraphNode::save`]) and take it back
/// ([`GraphNode::load`]): what the run core's capture and restore are made of
/// (`crate::runcore`). One whose kind cannot (a Python node's objects, a ROS 2 node's
/// proxy, a program's own kind that does not say how) makes a capture a replay.
///
/// There is no other node type for a scheduler: every kind, built in or a program's own,
/// is a `RustNode` made into one of these by the graph ([`crate::graph::Graph::build`]).
pub struct GraphNode {
    core: NodeCore,
    work: NodeOf,
}

impl GraphNode {
    /// A node doing `work` (its kind's node, bound to its topics).
    pub fn new(core: NodeCore, work: NodeOf) -> GraphNode {
        GraphNode { core, work }
    }

    /// A node named `name` of rank `rank` at `rate` that does nothing when it ticks, with
    /// no topics, faults or compute time: the stand-in of a node whose ticks run in another
    /// process (the launcher's `crate::runcore::Follower`), and the bench's bare wait (the
    /// real clock's own floor, `ratelab bench`).
    pub fn idle(name: &str, rank: NodeId, rate: Rate) -> GraphNode {
        GraphNode::alone(name, rank, rate, |_| NodeOf::unbound(Idle))
    }

    /// A node around the work `make` gives (given the node's outbox), with liveliness and
    /// faults of its own (none shared with a graph): [`GraphNode::idle`], and the
    /// schedulers' tests.
    pub(crate) fn alone(
        name: &str,
        rank: NodeId,
        rate: Rate,
        make: impl FnOnce(&Outbox) -> NodeOf,
    ) -> GraphNode {
        // A book of no faults: it covers no node.
        let faults = crate::graph::faults::FaultBook::new(0, &[], |_| None);
        let outbox = Outbox::new();
        let work = make(&outbox);
        GraphNode::new(
            NodeCore {
                name: name.to_string(),
                id: rank,
                rate,
                liveliness: Arc::new(Liveliness::new(None)),
                faults: Arc::new(faults),
                outbox,
                compute: None,
            },
            work,
        )
    }

    /// Its name (from the graph file: `sensor`, `policy`, `actuator`, …).
    pub fn name(&self) -> &str {
        &self.core.name
    }

    /// Its tie-break rank among nodes due at the same instant, lower first: its index in the
    /// graph (`crate::graph::spec`'s tie-break order).
    pub fn priority(&self) -> u32 {
        self.core.id.0 as u32
    }

    /// Its rate (shared with the graph's handles: it can change while the graph runs).
    pub fn rate(&self) -> &Rate {
        &self.core.rate
    }

    /// One tick at run time `now`: nothing while a fault covers it (stalled or killed: no
    /// work, no liveliness), else its liveliness asserted (unless its kind is alive by what
    /// it delivers, a ROS 2 node's proxy) and its kind's tick run. [`Flow::Stop`] ends the
    /// run.
    ///
    /// # Panics
    /// When its kind's code failed ([`ratelab_core::ports::RustNode::tick`]); the
    /// schedulers catch it and end the run as "node X failed".
    pub fn tick(&mut self, now: Nanos) -> Flow {
        if self.core.faults.covers(self.core.id, now) {
            self.core.liveliness.fault_tick();
            return Flow::Continue; // stalled or killed: no work, no liveliness
        }
        if self.work.0.alive_by_ticking() {
            // An external node is alive when it delivers, not when its proxy ticks.
            self.core.liveliness.assert_at(now);
        }
        self.work.0.tick(now)
    }

    /// The compute time of the tick about to run, drawn per tick
    /// ([`ratelab_core::executor::ComputeTime`]); zero (none given) publishes at once.
    pub fn compute_time(&mut self) -> Nanos {
        self.core
            .compute
            .as_mut()
            .map_or(Nanos::ZERO, ComputeDraw::draw)
    }

    /// Hold what the next tick publishes until [`GraphNode::publish_held`] (the executor
    /// calls it before a tick with a compute time; see [`ratelab_core::publisher`]).
    pub fn hold_outputs(&mut self) {
        self.core.outbox.hold();
    }

    /// Publish what the held tick published, stamped `at` (the tick's end).
    pub fn publish_held(&mut self, at: Nanos) {
        self.core.outbox.release(at);
    }

    /// Its state now, between two instants, or `None` when its kind cannot say (see the
    /// type's docs). Topics, rates and liveliness are the graph's, captured apart.
    pub fn save(&self) -> Option<NodeState> {
        Some(Box::new(Saved {
            work: self.work.0.save()?,
            outbox: self.core.outbox.save(),
            compute: self.core.compute.clone(),
        }))
    }

    /// Take back a state [`GraphNode::save`] gave. False (and nothing changed) when `state`
    /// is not one of this node's.
    pub fn load(&mut self, state: &NodeState) -> bool {
        let Some(s) = state.downcast_ref::<Saved>() else {
            return false;
        };
        if !self.work.0.load(&s.work) {
            return false;
        }
        self.core.outbox.load(&s.outbox);
        self.core.compute.clone_from(&s.compute);
        true
    }

    /// Give its ticks a compute time of `each` (the schedulers' tests).
    #[cfg(test)]
    pub(crate) fn set_compute(&mut self, each: Nanos) {
        let time = ratelab_core::executor::ComputeTime {
            mean: each,
            jitter: Nanos::ZERO,
        };
        self.core.compute = Some(ComputeDraw::new(time, 0, self.core.id.0));
    }
}

/// The kind of [`GraphNode::idle`]: no topics, no work, nothing kept.
struct Idle;

impl ratelab_core::ports::RustNode for Idle {
    type Input = ();
    type Output = ();
    fn tick(&mut self, _now: Nanos, _input: ()) {}
    fn save(&self) -> Option<NodeState> {
        Some(Box::new(()))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        state.is::<()>()
    }
}

/// A [`GraphNode`]'s state ([`GraphNode::save`]): its kind's, what its outbox holds, and its
/// compute-time generator. Its name, rank and handles never change; its rate, liveliness
/// and faults are the graph's ([`crate::runcore`] captures them).
struct Saved {
    work: NodeState,
    outbox: ratelab_core::publisher::OutboxState,
    compute: Option<ComputeDraw>,
}
