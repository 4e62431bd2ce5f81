//! Ids of a graph's nodes and topics, and the bounds on how many a graph may have.
//!
//! A leaf: the graph, the per-tick record ([`crate::runlog`]) and the metrics all index by
//! these, so they live below all three.

use serde::{Deserialize, Serialize};

pub use crate::limits::{MAX_NODES, MAX_TOPICS};

/// Index of a node in the graph's node list (`GraphSpec::nodes`), which is the tie-break
/// order; below [`MAX_NODES`] in a validated graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct NodeId(pub usize);

/// Index of a topic in the graph's topic list (`GraphSpec::topics`, file order); below
/// [`MAX_TOPICS`] in a validated graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct TopicId(pub usize);
