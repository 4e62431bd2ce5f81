//! A clock switch in place: the virtual scheduler hands a running graph to the real-clock
//! executor ([`super::run_real`]) at the instant it has reached, and takes it back when the
//! real clock stops, so that one run goes on under the other clock with every node's,
//! topic's and counter's state as it was (`ratelab::runcore::RunCore::run_real`).
//!
//! The real-clock executor keeps no timers of its own across runs: what it needs is each
//! node's next deadline (its first under the real clock), and what the virtual scheduler
//! needs back is the time the real clock stopped at and each node's ticks there.

use super::VirtualScheduler;
use crate::graph::nodes::GraphNode;
use ratelab_core::executor::{Dispatch, ExecutionPlan};
use ratelab_core::rate::first_on_grid;
use ratelab_core::time::Nanos;
use std::cmp::Reverse;

impl VirtualScheduler {
    /// The executors' plan the scheduler runs on now (the graph's, or one a command asked
    /// for since).
    pub fn plan(&self) -> &ExecutionPlan {
        self.dispatch.plan()
    }

    /// True when the executors' figures are measured (executors or compute times).
    pub fn tracks(&self) -> bool {
        self.track
    }

    /// Hand the graph over to another clock at the newest instant run ([`Self::now`]),
    /// between instants. Returns each node's next deadline, run time, by node index: its
    /// timer's due time (a tick released but still waiting for a thread is due at once).
    ///
    /// A tick still computing at the hand-over (its compute time not yet elapsed under the
    /// virtual clock) publishes its held outputs now, stamped now: the other clock has no
    /// event to end it at. Every thread is then free. The scheduler is left as it was
    /// otherwise; [`Self::take_over`] makes it current again.
    pub fn hand_over(&mut self, nodes: &mut [GraphNode]) -> Vec<Nanos> {
        let now = self.now;
        while let Some(Reverse((_, i))) = self.completions.pop() {
            if let Some(n) = nodes.get_mut(i) {
                n.publish_held(now);
            }
            self.ended(i, self.running_release[i], self.running_start[i], now);
        }
        self.instant_open = false;
        self.next_call.clone()
    }

    /// Take the graph back at run time `at` from another clock, on which node `i` ran
    /// `ticked[i]` ticks on the grid through `deadlines[i]` (its last deadline there, or the
    /// first, [`Self::hand_over`]'s, if it never ticked): the clock moves to `at`, each
    /// node's tick count grows by its ticks there, and each node's next tick is the first
    /// point after `at` of that grid at `periods[i]`, its period now (a node whose first
    /// deadline is after `at` keeps it; a phase change waiting for its tick takes effect).
    /// Nothing is released or running; the executors' plan and their figures so far are
    /// kept, and their utilization spans the virtual clock's time only (what the other
    /// clock measured is its own: [`ratelab_core::metrics::NodeTiming`]).
    ///
    /// Missing entries of `deadlines`, `ticked` or `periods` count as zero ticks and the
    /// node's timer as it was.
    pub fn take_over(&mut self, at: Nanos, deadlines: &[Nanos], ticked: &[u64], periods: &[Nanos]) {
        self.away = self.away.saturating_add(at.saturating_sub(self.now));
        self.now = self.now.max(at);
        for (i, t) in self.ticks.iter_mut().enumerate() {
            *t = t.saturating_add(ticked.get(i).copied().unwrap_or(0));
        }
        let after = at.saturating_add(Nanos(1));
        for i in 0..self.next_call.len() {
            if let (Some(&first), Some(&period)) = (deadlines.get(i), periods.get(i)) {
                // A phase change still waiting for the node's tick takes effect now.
                let grid = self.regrid[i].take().unwrap_or(first);
                self.next_call[i] = first_on_grid(grid, period, after);
            }
        }
        self.completions.clear();
        self.regrid.iter_mut().for_each(|r| *r = None);
        self.dispatch = Dispatch::new(self.dispatch.plan().clone(), &self.ranks);
        self.releases = self
            .next_call
            .iter()
            .enumerate()
            .map(|(i, &due)| Reverse((due, self.ranks[i], i)))
            .collect();
        self.instant_open = false;
    }
}
