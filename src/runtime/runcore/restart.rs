//! Nodes restarted in place: a running graph takes new code for some of its nodes (a saved
//! Python node, a node's parameters) without starting again from t = 0, as a process of a
//! graph is restarted while the others run on. The lab does this under the real clock on a
//! save (`ratelab::session`'s reload), where a run cannot start again alike.

use super::RunCore;
use crate::graph::{Graph, GraphSpec};
use std::sync::Arc;

impl RunCore {
    /// Restart nodes `which` (graph indices) in place, between instants or between two
    /// real-clock runs ([`RunCore::run_real`]), on `spec`: the run's graph with new code or
    /// parameters for them. Each is built afresh ([`Graph::rebuild_node`]: its state new, on
    /// the graph's topics, rate, liveliness and faults) and takes the old one's place and
    /// its timers; every other node, the topics, the plant and the counters go on as they
    /// were. The run is then the new code's from now: the captures kept for seeking are
    /// forgotten (one kept before would run the new code before its time), and a capture
    /// that replays cannot give the run ([`super::RestoreError::Replay`]).
    ///
    /// # Errors
    /// A one-line description, the run unchanged: `spec` is not the run's graph but for
    /// code and parameters ([`GraphSpec::same_shape`]), an index is out of range or the
    /// actuator's (it steps the plant and holds the run's step observers), a node's code
    /// does not load, or the run has ended.
    pub fn restart_nodes(&mut self, spec: &GraphSpec, which: &[usize]) -> Result<(), String> {
        if self.end.is_some() {
            return Err("the run has ended".into());
        }
        self.cfg.graph.same_shape(spec)?;
        if let Some(&i) = which.iter().find(|&&i| i >= self.nodes.len()) {
            return Err(format!("no node {i} in the graph"));
        }
        if which.contains(&spec.actuator.0) {
            // It steps the plant and tells the run's observers (the lab, a recording).
            return Err("the actuator cannot restart in place: it holds the run's steps".into());
        }
        let mut handles = self.handles.clone();
        handles.spec = Arc::new(spec.clone());
        let fresh = which
            .iter()
            .map(|&i| Graph::rebuild_node(&handles, self.cfg.seed, i).map(|n| (i, n)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| e.to_string())?;
        for (i, node) in fresh {
            self.nodes[i] = node;
        }
        self.handles.spec = handles.spec;
        self.cfg.graph = spec.clone();
        let now = self.sched.now();
        self.real_parts.push((now, now));
        self.history.clear();
        self.next_history = now;
        Ok(())
    }
}
