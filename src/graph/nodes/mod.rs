//! The node kinds at run time: what each does on a tick (ch2.8's node classes, generalized),
//! one file each: [`sensor`], [`estimator`], [`policy`], [`safety`], [`actuator`]; a
//! Python node is [`crate::python::node`], a registered one [`super::registry`]; an
//! external node, run by another program over ROS 2, enters through [`external`].
//!
//! A **python** node runs its subscription callbacks for what arrived, then its timers; a
//! **registered** kind its `tick` for what arrived; what either published goes out with the
//! oldest origin among its inputs' newest messages (either may have several inputs and
//! outputs; every other kind has at most one of each).
//!
//! Every node that publishes passes on the origin stamp of the message it derived its output
//! from (of several inputs, the oldest), so the actuator measures sense→act latency
//! (`now − origin`) across any chain.
//!
//! Adding a built-in kind is a file here, its variant in [`Work`], its name in
//! [`super::spec::NodeKind`] and its wiring in [`super::Graph::build`]; a kind written outside
//! ratelab needs none of that ([`super::registry`]).

pub mod actuator;
pub mod estimator;
pub mod external;
pub mod policy;
pub mod safety;
pub mod sensor;

pub use actuator::Actuator;
pub use estimator::Estimator;
pub use external::{External, ExternalPort};
pub use policy::PolicyNode;
pub use safety::Safety;
pub use sensor::{Sensor, SensorNoise, SensorOutput};

use super::spec::NodeId;
use crate::executor::ComputeDraw;
use crate::node::{Flow, Node};
use crate::publisher::Outbox;
use crate::qos::{Fault, Liveliness};
use crate::rate::Rate;
use crate::time::Nanos;
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
    /// Faults injected into it (`--stall`, `--kill`).
    pub faults: Vec<Fault>,
    /// Its publishers' outbox (held during a tick with a compute time).
    pub outbox: Outbox,
    /// Its compute time's draws; `None`: its ticks take no time.
    pub compute: Option<ComputeDraw>,
}

/// A node of some kind around its [`NodeCore`].
pub struct GraphNode {
    core: NodeCore,
    work: Work,
}

/// The kind-specific state: one variant per kind, each kind's tick in its own file.
pub enum Work {
    /// See [`sensor`].
    Sensor(Sensor),
    /// See [`estimator`].
    Estimator(Estimator),
    /// See [`policy`].
    Policy(PolicyNode),
    /// See [`safety`].
    Safety(Safety),
    /// See [`actuator`].
    Actuator(Box<Actuator>),
    /// A learner's node in Python ([`crate::python::node`]).
    Python(Box<crate::python::node::PythonNode>),
    /// A node of a kind registered in Rust ([`super::registry`]), bound to its topics.
    Registered(Box<dyn super::registry::Tick>),
    /// A node another program runs over ROS 2 ([`external`]): its proxy.
    External(Box<External>),
}

impl GraphNode {
    /// A node of `work`'s kind.
    pub fn new(core: NodeCore, work: Work) -> GraphNode {
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
        if self.core.faults.iter().any(|f| f.covers(now)) {
            self.core.liveliness.fault_tick();
            return Flow::Continue; // stalled or killed: no work, no liveliness
        }
        if !matches!(self.work, Work::External(_)) {
            // An external node is alive when it delivers, not when its proxy ticks.
            self.core.liveliness.assert_at(now);
        }
        match &mut self.work {
            Work::Sensor(s) => s.tick(now),
            Work::Estimator(e) => e.tick(now),
            Work::Policy(p) => p.tick(now),
            Work::Safety(s) => s.tick(now),
            Work::Actuator(a) => a.tick(now),
            Work::External(x) => x.tick(now),
            Work::Registered(r) => {
                r.tick(now);
                Flow::Continue
            }
            Work::Python(p) => match p.tick(now, self.core.rate.period()) {
                Ok(()) => Flow::Continue,
                // The scheduler catches it and fails the node with this line.
                Err(e) => panic!("{}", e.0),
            },
        }
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
}
