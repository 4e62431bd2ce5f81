//! The run core's graph under the real clock: its nodes handed to the real-clock executor
//! ([`crate::scheduler::run_real`]: a thread per node, or the executors' threads) for the
//! run, and taken back when it ends. The headless run, the lab's engine and each process of
//! a launch run the real clock through here, as they run the virtual clock through
//! [`super::RunCore::step`] and [`super::RunCore::next_event`].

use super::RunCore;
use crate::executor::ExecFigures;
use crate::metrics::NodeTiming;
use crate::node::Node;
use crate::scheduler::{run_real, RealOptions, RunEnd, StopFlag};

/// What a real-clock run of a run core measured ([`RunCore::run_real`]).
pub struct RealEnd {
    /// How it ended.
    pub end: RunEnd,
    /// Per node that ran, in graph order, its tick timing.
    pub timing: Vec<NodeTiming>,
    /// What the executors measured, when [`RealOptions::track`] (and no node thread died).
    pub exec: Option<ExecFigures>,
}

impl RunCore {
    /// Run the graph under the real clock, from its start, on `opts`'s executors, until the
    /// run's duration, a node stopping the graph (the fall), a node failing, or `stop`;
    /// `part`: only these nodes (graph indices, ascending: a process's share of a graph
    /// across processes, whose other nodes run in their own processes), else all.
    ///
    /// The nodes come back into the core when the run ends, which is then over
    /// ([`RunCore::end`]; a node that panicked does not come back, and the core then holds
    /// fewer nodes: restoring a capture into it fails); the graph's handles ([`RunCore::handles`]) hold what it
    /// measured. A core whose run has ended runs nothing: its end comes back, with no
    /// timing. Commands given in advance are the virtual clock's: a real-clock run takes
    /// its commands as they come, applied to the handles.
    pub fn run_real(
        &mut self,
        part: Option<&[usize]>,
        stop: &StopFlag,
        opts: &RealOptions,
    ) -> RealEnd {
        if let Some(end) = &self.end {
            // A run is run once (a node that panicked is gone from it).
            return RealEnd {
                end: end.clone(),
                timing: Vec::new(),
                exec: None,
            };
        }
        let all = std::mem::take(&mut self.nodes);
        let mut slots: Vec<Option<Box<dyn Node>>> = all.into_iter().map(Some).collect();
        let index: Vec<usize> = match part {
            Some(p) => p.iter().copied().filter(|&i| i < slots.len()).collect(),
            None => (0..slots.len()).collect(),
        };
        let running: Vec<Box<dyn Node>> = index.iter().filter_map(|&i| slots[i].take()).collect();
        let run = run_real(running, self.cfg.duration, stop, opts);
        // Back in their places, by name (unique in a graph): a node whose thread died (it
        // panicked) does not come back, and the run has ended with it.
        for node in run.nodes {
            let name = node.name();
            if let Some(&i) = index
                .iter()
                .find(|&&i| self.cfg.graph.nodes[i].name == name)
            {
                slots[i] = Some(node);
            }
        }
        self.nodes = slots.into_iter().flatten().collect();
        self.end = Some(run.end.clone());
        RealEnd {
            end: run.end,
            timing: run.timing,
            exec: run.exec,
        }
    }
}
