//! The faults of a run's nodes, in one book the graph's nodes and its handles share: those
//! of the run's settings (`--stall NODE@T+D`, `--kill NODE@T`) from its start, and those a
//! command injects while it runs ([`crate::command::Command::InjectFault`]: the lab, a
//! replayed session log). A faulted tick does no work and asserts no liveliness (a stalled
//! or killed node, as a liveliness lease and a deadline watchdog see it).
//!
//! A tick asks the book whether it is faulted: for a node with no fault (every node of
//! almost every run) that is one relaxed atomic load; the book is locked only for a node
//! that has one.

use ratelab_core::ids::NodeId;
use ratelab_core::qos::Fault;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// The faults of a run's nodes (module docs).
#[derive(Debug, Default)]
pub struct FaultBook {
    /// Per node (by id), true once a fault of its is in the book.
    faulted: Vec<AtomicBool>,
    /// Each fault with its node, those of the settings first.
    faults: Mutex<Vec<(NodeId, Fault)>>,
    /// How many of them the settings gave (the rest were injected, in order).
    from_settings: usize,
}

impl FaultBook {
    /// A book for `nodes` nodes holding the run's settings' `faults`, each with its node's
    /// id (faults whose node `id_of` does not know, or gives an id of no node, are left
    /// out: the settings' validation refuses them).
    pub fn new(
        nodes: usize,
        faults: &[Fault],
        id_of: impl Fn(&str) -> Option<NodeId>,
    ) -> FaultBook {
        let faults: Vec<(NodeId, Fault)> = faults
            .iter()
            .filter_map(|f| Some((id_of(&f.node).filter(|id| id.0 < nodes)?, f.clone())))
            .collect();
        let faulted = (0..nodes)
            .map(|i| AtomicBool::new(faults.iter().any(|(n, _)| n.0 == i)))
            .collect();
        FaultBook {
            faulted,
            from_settings: faults.len(),
            faults: Mutex::new(faults),
        }
    }

    /// True when node `node`'s tick at run time `now` is swallowed by a fault.
    pub fn covers(&self, node: NodeId, now: ratelab_core::time::Nanos) -> bool {
        self.faulted
            .get(node.0)
            .is_some_and(|f| f.load(Ordering::Relaxed))
            && crate::graph::lock(&self.faults)
                .iter()
                .any(|(n, f)| *n == node && f.covers(now))
    }

    /// Add `fault` on node `node` while the run goes on: it takes effect at its time (a time
    /// already past covers the ticks from now on that it would have covered).
    ///
    /// # Errors
    /// One line when the book holds [`ratelab_core::qos::MAX_FAULTS`] faults already, or `node`
    /// is no node of the graph.
    pub fn inject(&self, node: NodeId, fault: Fault) -> Result<(), String> {
        let Some(flag) = self.faulted.get(node.0) else {
            return Err(format!("no node {} in the graph", node.0));
        };
        let mut faults = crate::graph::lock(&self.faults);
        if faults.len() >= ratelab_core::qos::MAX_FAULTS {
            let most = ratelab_core::qos::MAX_FAULTS;
            let line = format_args!("a run holds at most {most} faults");
            return Err(ratelab_core::limits::refusal(line, "MAX_FAULTS"));
        }
        faults.push((node, fault));
        flag.store(true, Ordering::Relaxed);
        Ok(())
    }

    /// The faults injected so far, in order (not those of the settings).
    pub fn injected(&self) -> Vec<Fault> {
        crate::graph::lock(&self.faults)[self.from_settings..]
            .iter()
            .map(|(_, f)| f.clone())
            .collect()
    }

    /// What a capture keeps of the book: the faults injected so far, with their nodes.
    pub fn save(&self) -> Vec<(NodeId, Fault)> {
        crate::graph::lock(&self.faults)[self.from_settings..].to_vec()
    }

    /// Put back the faults injected as `saved` ([`FaultBook::save`]) had them.
    pub fn load(&self, saved: &[(NodeId, Fault)]) {
        let mut faults = crate::graph::lock(&self.faults);
        faults.truncate(self.from_settings);
        faults.extend(
            saved
                .iter()
                .filter(|(n, _)| n.0 < self.faulted.len())
                .cloned(),
        );
        for (i, flag) in self.faulted.iter().enumerate() {
            flag.store(faults.iter().any(|(n, _)| n.0 == i), Ordering::Relaxed);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::time::Nanos;

    fn stall(node: &str, at_s: u64, for_s: u64) -> Fault {
        Fault {
            node: node.into(),
            at: Nanos(at_s * Nanos::SECOND.0),
            duration: Some(Nanos(for_s * Nanos::SECOND.0)),
        }
    }

    #[test]
    fn a_tick_is_faulted_only_by_its_own_node_s_faults_in_their_time() {
        let id = |name: &str| {
            ["sensor", "policy"]
                .iter()
                .position(|n| *n == name)
                .map(NodeId)
        };
        let book = FaultBook::new(2, &[stall("policy", 2, 1), stall("nobody", 0, 9)], id);
        let s = |t: u64| Nanos(t * Nanos::SECOND.0);
        assert!(!book.covers(NodeId(1), s(1)));
        assert!(book.covers(NodeId(1), s(2)));
        assert!(!book.covers(NodeId(1), s(3)), "a stall ends");
        assert!(!book.covers(NodeId(0), s(2)), "another node's fault");
        assert!(book.injected().is_empty());

        let kill = Fault {
            node: "sensor".into(),
            at: s(5),
            duration: None,
        };
        book.inject(NodeId(0), kill.clone()).unwrap();
        assert!(book.covers(NodeId(0), s(9)), "a kill lasts");
        assert_eq!(book.injected(), vec![kill.clone()]);
        let saved = book.save();
        book.load(&[]);
        assert!(
            !book.covers(NodeId(0), s(9)),
            "restored to before the injection"
        );
        assert!(book.covers(NodeId(1), s(2)), "the settings' faults stay");
        book.load(&saved);
        assert!(book.covers(NodeId(0), s(9)));
    }

    #[test]
    fn an_empty_book_faults_nothing_and_is_bounded() {
        let book = FaultBook::new(1, &[], |_| None);
        assert!(!book.covers(NodeId(0), Nanos::ZERO));
        for k in 0..ratelab_core::qos::MAX_FAULTS {
            book.inject(NodeId(0), stall("sensor", k as u64, 1))
                .unwrap();
        }
        assert!(book.inject(NodeId(0), stall("sensor", 0, 1)).is_err());
        assert!(
            book.inject(NodeId(1), stall("sensor", 0, 1)).is_err(),
            "no such node"
        );
    }
}
