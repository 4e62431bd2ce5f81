//! Ids of a graph's nodes and topics, and the bounds on how many a graph may have.
//!
//! A leaf: the graph, the per-tick record ([`crate::runlog`]) and the metrics all index by
//! these, so they live below all three.

use serde::{Deserialize, Serialize};

/// The most nodes a graph may have (the lab lays out up to this many).
pub const MAX_NODES: usize = 8;
/// The most topics a graph may have: every node but the actuator publishes at most one.
pub const MAX_TOPICS: usize = MAX_NODES - 1;

/// Index of a node in the graph's node list (`GraphSpec::nodes`), which is the tie-break
/// order; below [`MAX_NODES`] in a validated graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct NodeId(pub usize);

/// Index of a topic in the graph's topic list (`GraphSpec::topics`, file order); below
/// [`MAX_TOPICS`] in a validated graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct TopicId(pub usize);
