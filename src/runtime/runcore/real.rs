//! The run core's graph under the real clock: its nodes handed to the real-clock executor
//! ([`crate::scheduler::run_real`]: a thread per node, or the executors' threads) for the
//! run, and taken back when it ends. The headless run, the lab's engine and each process of
//! a launch run the real clock through here, as they run the virtual clock through
//! [`super::RunCore::step`] and [`super::RunCore::next_event`].

use super::RunCore;
use crate::graph::nodes::GraphNode;
use crate::scheduler::{run_real, EndReason, RealOptions, RunEnd, StopFlag, TickReport};
use ratelab_core::executor::ExecFigures;
use ratelab_core::metrics::NodeTiming;
use ratelab_core::time::Nanos;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

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
    /// Run the graph under the real clock from the instant the core has reached, on
    /// `opts`'s executors, until the run's duration, a node stopping the graph (the fall), a
    /// node failing, or `stop`; `part`: only these nodes (graph indices, ascending: a
    /// process's share of a graph across processes, whose other nodes run in their own
    /// processes), else all.
    ///
    /// - The whole graph (`part` `None`) runs on its own timers and executors as the
    ///   scheduler has them, commands since the start included: each node's first deadline
    ///   is its next tick there, on the executors' plan it runs
    ///   ([`VirtualScheduler::hand_over`]); `opts`'s phase offsets, plan and measuring are
    ///   not read. A process's share from t = 0 runs on `opts`'s (the launch's grid, a late
    ///   joiner's included).
    /// - **From t = 0** (nothing run yet) the run's zero instant is `opts`'s
    ///   ([`RealOptions::start`], which processes of one graph share).
    /// - **From an instant t the virtual clock reached** (a clock switch in place) the real
    ///   clock reads t now and goes on from there; the executors' figures span from t
    ///   ([`RealOptions::from`]). A machine up for less than t (its monotonic clock cannot
    ///   read t now) runs nothing: the run is interrupted at t, not ended.
    ///
    /// The nodes come back into the core when the run ends (a node that panicked does not
    /// come back, and the core then holds fewer nodes: restoring a capture into it fails);
    /// the core is then at the time the real clock stopped, t′, its scheduler's tick counts
    /// ([`RunCore::scheduler`]) including the real clock's. A run that `stop` interrupted
    /// can go on, each node's next tick the first after t′ on the grid it ran on (through
    /// its last real-clock deadline, at its period now: [`VirtualScheduler::take_over`]), so that [`RunCore::step`] goes
    /// on under the virtual clock (or `run_real` again under the real one) with every
    /// node's, topic's, counter's and the plant's state as the real clock left it. Any other
    /// end (duration, fall, failure) ends the core's run ([`RunCore::end`]); a core whose
    /// run has ended runs nothing: its end comes back, with no timing.
    ///
    /// The graph's handles ([`RunCore::handles`]) hold what the real clock measured.
    /// Commands given in advance are the virtual clock's: a real-clock run takes its
    /// commands as they come, applied to the handles. Captures are not kept while the real
    /// clock runs, and a capture that replays cannot give a run that ran under it
    /// ([`RestoreError::Replay`]).
    ///
    /// [`VirtualScheduler::hand_over`]: crate::scheduler::VirtualScheduler::hand_over
    /// [`VirtualScheduler::take_over`]: crate::scheduler::VirtualScheduler::take_over
    /// [`RestoreError::Replay`]: super::RestoreError::Replay
    pub fn run_real(
        &mut self,
        part: Option<&[usize]>,
        stop: &StopFlag,
        opts: &RealOptions,
    ) -> RealEnd {
        if let Some(end) = &self.end {
            // A run is run to its end once (a node that panicked is gone from it).
            return RealEnd {
                end: end.clone(),
                timing: Vec::new(),
                exec: None,
            };
        }
        let from = self.sched.now();
        let resumed = from > Nanos::ZERO || self.sched.ticks().iter().any(|&t| t > 0);
        let deadlines = self.sched.hand_over(&mut self.nodes);
        let all = std::mem::take(&mut self.nodes);
        let mut slots: Vec<Option<GraphNode>> = all.into_iter().map(Some).collect();
        let index: Vec<usize> = match part {
            Some(p) => p.iter().copied().filter(|&i| i < slots.len()).collect(),
            None => (0..slots.len()).collect(),
        };
        let mut opts = opts.clone();
        if resumed || part.is_none() {
            // The graph's own timers and executors as the scheduler has them (commands may
            // have changed them since the start); a process's share keeps the launch's.
            opts.phase_offsets = index.iter().map(|&i| deadlines[i]).collect();
            opts.plan = Some(self.sched.plan().restricted(&index));
            opts.track = self.sched.tracks();
        }
        if resumed {
            let Some(start) = std::time::Instant::now().checked_sub(from.to_duration()) else {
                self.nodes = slots.into_iter().flatten().collect();
                return RealEnd {
                    end: RunEnd {
                        at: from,
                        reason: EndReason::Interrupted,
                    },
                    timing: Vec::new(),
                    exec: None,
                };
            };
            opts.start = Some(start);
            opts.from = from;
        }
        // Each node's last deadline under the real clock (its grid, for the virtual clock
        // to take it back on), kept as each tick is told.
        let last: Arc<Vec<AtomicU64>> = Arc::new(
            index
                .iter()
                .map(|&i| AtomicU64::new(deadlines[i].0))
                .collect(),
        );
        let told = opts.on_tick.take();
        let keep = last.clone();
        opts.on_tick = Some(Arc::new(move |t: &TickReport<'_>| {
            if let Some(d) = keep.get(t.node) {
                d.store(t.now.saturating_sub(t.lateness).0, Ordering::Relaxed);
            }
            if let Some(hook) = &told {
                hook(t);
            }
        }));
        let running: Vec<GraphNode> = index.iter().filter_map(|&i| slots[i].take()).collect();
        let count = running.len();
        let run = run_real(running, self.cfg.duration, stop, &opts);
        // Back in their places, by name (unique in a graph): a node whose thread died (it
        // panicked) does not come back, and the run has ended with it.
        let came_back = run.nodes.len();
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
        // The scheduler takes the graph back at the time the real clock stopped: its tick
        // counts include the real clock's, and a run that was only interrupted (a clock
        // switch, or a stop the driver may follow by ending the run) goes on from there.
        let mut ticked = vec![0u64; self.sched.ticks().len()];
        let mut grid = deadlines;
        for (k, (&i, t)) in index.iter().zip(&run.timing).enumerate() {
            ticked[i] = t.ticks;
            grid[i] = Nanos(last[k].load(Ordering::Relaxed));
        }
        let periods: Vec<Nanos> = self.handles.rates.iter().map(|r| r.period()).collect();
        self.sched.take_over(run.end.at, &grid, &ticked, &periods);
        if run.end.reason == EndReason::Interrupted && came_back == count {
            self.real_parts.push((from, run.end.at));
            self.next_history = self.next_history.max(run.end.at);
        } else {
            self.end = Some(run.end.clone());
        }
        RealEnd {
            end: run.end,
            timing: run.timing,
            exec: run.exec,
        }
    }
}
