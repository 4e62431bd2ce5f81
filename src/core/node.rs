//! Nodes: a unit of work with a name, a rate, a tie-break priority and a `tick`.
//!
//! Nodes talk to each other only through topics they were handed (publishing through a
//! [`crate::publisher::Publisher`]). A scheduler (virtual or real, see `ratelab::scheduler`)
//! calls [`Node::tick`] at the node's rate, on the thread its executor gives it
//! ([`crate::executor`]); a tick with a compute time publishes at its end. The
//! priority breaks ties between nodes due at the same instant: lower ticks first, so the
//! chapter's order sensor (0) → policy (1) → actuator (2) samples, thinks, then acts.
//! The node kinds of a graph are in `ratelab::graph::nodes`.
//!
//! A node may also give its state at an instant ([`Node::save`]) and take it back
//! ([`Node::load`]): what the run core's capture and restore are made of
//! (`ratelab::runcore`). A node that cannot (the default: a Python node's objects, a ROS 2
//! node's proxy, a program's own kind that does not say how) makes a capture a replay.

use crate::rate::Rate;
use crate::time::Nanos;
use std::any::Any;

/// A node's state at an instant, as [`Node::save`] gives it: whatever the node needs to go
/// on from there as if it had never stopped (counters, held values, generators). Only the
/// node that saved it reads it back ([`Node::load`]).
pub type NodeState = Box<dyn Any + Send + Sync>;

/// What the scheduler should do after a tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Keep running.
    Continue,
    /// Stop the whole graph (the actuator returns this when the pole falls).
    Stop,
}

/// A node of the graph.
pub trait Node: Send {
    /// The node's name (from the graph file: `sensor`, `policy`, `actuator`, …).
    fn name(&self) -> &str;
    /// Tie-break rank among nodes due at the same instant; lower first (a graph's nodes
    /// carry their index in the tie-break order, see `ratelab::graph::spec`).
    fn priority(&self) -> u32;
    /// The node's rate (shared: it can change while the graph runs).
    fn rate(&self) -> &Rate;
    /// Do one tick's work at run time `now`.
    fn tick(&mut self, now: Nanos) -> Flow;
    /// The compute time of the tick about to run, drawn per tick
    /// ([`crate::executor::ComputeTime`]); zero (the default) publishes its outputs at once.
    fn compute_time(&mut self) -> Nanos {
        Nanos::ZERO
    }
    /// Hold what the next tick publishes until [`Node::publish_held`] (the executor calls it
    /// before a tick with a compute time; see [`crate::publisher`]).
    fn hold_outputs(&mut self) {}
    /// Publish what the held tick published, stamped `at` (the tick's end).
    fn publish_held(&mut self, _at: Nanos) {}
    /// The node's state now, between two instants, or `None` when it cannot be captured
    /// (the default). Topics, rates and liveliness are the graph's, captured apart.
    fn save(&self) -> Option<NodeState> {
        None
    }
    /// Take back a state [`Node::save`] gave. Returns false (and changes nothing) when
    /// `state` is not one of this node's.
    fn load(&mut self, _state: &NodeState) -> bool {
        false
    }
}
