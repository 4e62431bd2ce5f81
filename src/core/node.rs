//! What a node's tick tells its scheduler ([`Flow`]) and what a node's state is between two
//! instants ([`NodeState`]).
//!
//! A node is written as a [`crate::ports::RustNode`] (typed inputs and outputs, one `tick`):
//! every built-in kind, a program's own, and the adapters (a Python node, a ROS 2 node's
//! proxy). A graph makes each into the one node type its schedulers run
//! (`ratelab::graph::nodes::GraphNode`).

use std::any::Any;

/// A node's state at an instant, as [`crate::ports::RustNode::save`] gives it: whatever the
/// node needs to go on from there as if it had never stopped (counters, held values,
/// generators). Only the node that saved it reads it back ([`crate::ports::RustNode::load`]).
pub type NodeState = Box<dyn Any + Send + Sync>;

/// What the scheduler should do after a tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Keep running.
    Continue,
    /// Stop the whole graph (the actuator returns this when the pole falls).
    Stop,
}
