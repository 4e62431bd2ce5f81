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
use ratelab_core::node::{Flow, Node, NodeState};
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

/// A node of some kind around its [`NodeCore`]: what the scheduler runs.
pub struct GraphNode {
    core: NodeCore,
    work: NodeOf,
}

impl GraphNode {
    /// A node doing `work` (its kind's node, bound to its topics).
    pub fn new(core: NodeCore, work: NodeOf) -> GraphNode {
        GraphNode { core, work }
    }
}

impl Node for GraphNode {
    fn name(&self) -> &str {
        &self.core.name
    }
    fn priority(&self) -> u32 {
        self.core.id.0 as u32
    }
    fn rate(&self) -> &Rate {
        &self.core.rate
    }
    fn tick(&mut self, now: Nanos) -> Flow {
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
    fn compute_time(&mut self) -> Nanos {
        self.core
            .compute
            .as_mut()
            .map_or(Nanos::ZERO, ComputeDraw::draw)
    }
    fn hold_outputs(&mut self) {
        self.core.outbox.hold();
    }
    fn publish_held(&mut self, at: Nanos) {
        self.core.outbox.release(at);
    }
    fn save(&self) -> Option<NodeState> {
        Some(Box::new(Saved {
            work: self.work.0.save()?,
            outbox: self.core.outbox.save(),
            compute: self.core.compute.clone(),
        }))
    }
    fn load(&mut self, state: &NodeState) -> bool {
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
}

/// A [`GraphNode`]'s state ([`Node::save`]): its kind's, what its outbox holds, and its
/// compute-time generator. Its name, rank and handles never change; its rate, liveliness
/// and faults are the graph's ([`crate::runcore`] captures them).
struct Saved {
    work: NodeState,
    outbox: ratelab_core::publisher::OutboxState,
    compute: Option<ComputeDraw>,
}
