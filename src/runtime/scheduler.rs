//! The two clocks that run one graph, by the executors' rules ([`ratelab_core::executor`]).
//!
//! - [`VirtualScheduler`]: a discrete-event model over a virtual clock (ch2.8,
//!   `run_virtual`). A min-heap of `(due, priority, index)`: pop the earliest, stop if it is
//!   due after the run's end, tick it, stop the world on [`Flow::Stop`], push it back at
//!   `due + period` (the period read *now*, so a rate change takes effect from the node's
//!   next tick). Time is integer nanoseconds, so ties are exact and broken by priority then
//!   index: same settings → the same interleaving → byte-identical runs. With executors or
//!   compute times the same instants also end ticks (their outputs go out) and hold ticks
//!   that wait for a thread, exactly and deterministically.
//! - [`run_real`]: by default one OS thread per node, each ticking against a monotonic
//!   clock at absolute deadlines (ch2.8, `run_real`); a single- or multi-threaded
//!   executor's nodes share its threads (`scheduler/real_clock/shared.rs`). Message interleaving then
//!   depends on the OS scheduler, so two runs with the same seed are **not** reproducible:
//!   drop counts and latencies vary by a handful. That is the nature of concurrency, not a
//!   bug; use the virtual clock to compare runs.

use ratelab_core::clock::{Clock, MonotonicClock};
mod real_clock;
mod virtual_clock;
pub use real_clock::{
    check_real_clock_threads, plan_threads, run_real, RealOptions, RealRun, TickHook, TickReport,
};
pub use virtual_clock::{Event, InstantOutcome, PlanRequest, VirtualScheduler};

use crate::graph::nodes::GraphNode;
use ratelab_core::executor::{
    CallbackSpan, Dispatch, ExecFigures, ExecutionPlan, ExecutorFigures, ExecutorKind,
    NodeExecFigures,
};
use ratelab_core::metrics::{LatencyStats, NodeTiming};
use ratelab_core::node::Flow;
use ratelab_core::rate::{first_on_grid, next_deadline, DeadlineWaiter};
use ratelab_core::time::Nanos;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// A shared stop request: set by a fall, Ctrl-C, the lab, or a failed node. Clones share
/// it; a [`StopFlag::child`] also reads as set once its parent is, and is set alone.
#[derive(Clone, Debug, Default)]
pub struct StopFlag {
    own: Arc<AtomicBool>,
    /// The flag this one was made from, if any: set, this one reads as set too.
    parent: Option<Arc<StopFlag>>,
}

impl StopFlag {
    /// A flag not yet set.
    pub fn new() -> Self {
        Self::default()
    }
    /// Ask every node loop to stop.
    pub fn stop(&self) {
        self.own.store(true, Ordering::SeqCst);
    }
    /// Has a stop been asked for, of this flag or of a flag it was made from?
    pub fn is_stopped(&self) -> bool {
        self.own.load(Ordering::SeqCst) || self.parent.as_ref().is_some_and(|p| p.is_stopped())
    }
    /// A flag for one run among several that one stop ends (Ctrl-C during a sweep or an
    /// exercise): set when this one is, while what sets it (a fall under the real clock,
    /// which stops that run's threads) leaves this one, and so the other runs, alone.
    pub fn child(&self) -> StopFlag {
        StopFlag {
            own: Arc::new(AtomicBool::new(false)),
            parent: Some(Arc::new(self.clone())),
        }
    }
}

/// Why a run ended.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum EndReason {
    /// The run reached its duration.
    Duration,
    /// A node returned [`Flow::Stop`] (the pole fell).
    NodeStopped,
    /// The stop flag was set from outside (Ctrl-C, the lab).
    Interrupted,
    /// A node panicked; its name and message.
    NodeFailed {
        /// The node.
        node: String,
        /// The panic message.
        message: String,
    },
}

impl EndReason {
    /// How the run ended, in words: as it displays ("the pole fell", "duration reached", …),
    /// except that a stop by the actuator's deadline watchdog (`watchdog`: the run's
    /// [`ratelab_core::metrics::Metrics::stopped_by_watchdog`] is set), which ends the run as a node's
    /// stop as a fall does, says "stopped by watchdog".
    pub fn words(&self, watchdog: bool) -> String {
        if watchdog {
            "stopped by watchdog".to_string()
        } else {
            self.to_string()
        }
    }
}

impl std::fmt::Display for EndReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EndReason::Duration => f.write_str("duration reached"),
            EndReason::NodeStopped => f.write_str("the pole fell"),
            EndReason::Interrupted => f.write_str("interrupted"),
            EndReason::NodeFailed { node, message } => write!(f, "node '{node}' failed: {message}"),
        }
    }
}

/// How a run ended and at what run time.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunEnd {
    /// Run time at the end: the stopping tick's time, or the duration.
    pub at: Nanos,
    /// Why.
    pub reason: EndReason,
}

/// What an executor measures of one node while it runs.
#[derive(Clone, Debug, Default)]
pub struct NodeExecStats {
    /// Skipped timer periods.
    pub skipped_ticks: u64,
    /// Response times (created at the first sample).
    pub response: Option<LatencyStats>,
    /// Compute time spent.
    pub busy: Nanos,
}

impl NodeExecStats {
    /// One tick released at `release` whose outputs went out at `done`, having computed for
    /// `busy`.
    pub fn record(&mut self, release: Nanos, done: Nanos, busy: Nanos) {
        self.response
            .get_or_insert_with(Default::default)
            .record(done.saturating_sub(release));
        self.busy = self.busy.saturating_add(busy);
    }
}

/// The figures of `stats` (by node) under `plan` over a run of `elapsed`.
pub fn figures(plan: &ExecutionPlan, stats: &[NodeExecStats], elapsed: Nanos) -> ExecFigures {
    let ms = |q: Option<Nanos>| q.map_or(0.0, |n| (n.as_millis_f64() * 1e3).round() / 1e3);
    let nodes = stats
        .iter()
        .map(|s| {
            let r = s.response.as_ref();
            NodeExecFigures {
                response_time_p50_ms: ms(r.and_then(|r| r.quantile(0.5))),
                response_time_p99_ms: ms(r.and_then(|r| r.quantile(0.99))),
                response_time_max_ms: ms(r.and_then(|r| r.max())),
                skipped_ticks: s.skipped_ticks,
                busy_ms: ms(Some(s.busy)),
            }
        })
        .collect();
    let executors = plan
        .executors
        .iter()
        .enumerate()
        .map(|(e, x)| {
            let busy: u64 = stats
                .iter()
                .enumerate()
                .filter(|(n, _)| plan.node_executor.get(*n) == Some(&e))
                .map(|(_, s)| s.busy.0)
                .sum();
            let available = elapsed.0 as f64 * x.threads as f64;
            ExecutorFigures {
                name: x.name.clone(),
                kind: x.kind,
                threads: x.threads,
                utilization: if available > 0.0 {
                    ((busy as f64 / available).min(1.0) * 1e4).round() / 1e4
                } else {
                    0.0
                },
            }
        })
        .collect();
    ExecFigures { nodes, executors }
}

thread_local! {
    /// Set while [`catch_quietly`] runs on this thread: its panics are caught, not printed.
    static QUIET_PANICS: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Run `f`, catching a panic inside it without printing it: the caller reports it (a node
/// that failed, a checkpoint reader that choked) in one line of its own. A wrapper around
/// the process's panic hook (installed once) stays silent while this thread is inside
/// `catch_quietly`, and defers to the previous hook everywhere else.
///
/// # Errors
/// The panic's payload (see [`panic_message`]).
pub fn catch_quietly<T>(f: impl FnOnce() -> T) -> std::thread::Result<T> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET_PANICS.with(std::cell::Cell::get) {
                previous(info);
            }
        }));
    });
    let was = QUIET_PANICS.with(|q| q.replace(true));
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET_PANICS.with(|q| q.set(was));
    result
}

/// The message of a caught panic, its control characters written out
/// ([`ratelab_core::text::printable`]): a node's code (a registered kind's, a learner's) says what
/// it likes, and the message reaches the summary, `metrics.json`, the lab and a recording.
pub fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    let message = p
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panic".to_string());
    ratelab_core::text::printable(&message).into_owned()
}

/// Nodes for the clocks' tests: each tick logged with its run time and name.
#[cfg(test)]
mod probes {
    use super::*;
    use crate::graph::kind::NodeOf;
    use ratelab_core::ids::NodeId;
    use ratelab_core::ports::RustNode;
    use ratelab_core::rate::Rate;
    use std::sync::Mutex;

    /// Logs each tick; stops the run from `stop_at` on.
    struct Probe {
        name: &'static str,
        log: Arc<Mutex<Vec<(u64, &'static str)>>>,
        stop_at: Option<Nanos>,
        last: Nanos,
    }

    impl RustNode for Probe {
        type Input = ();
        type Output = ();
        fn tick(&mut self, now: Nanos, _: ()) {
            self.last = now;
            self.log.lock().unwrap().push((now.0, self.name));
        }
        fn flow(&self) -> Flow {
            if self.stop_at.is_some_and(|t| self.last >= t) {
                Flow::Stop
            } else {
                Flow::Continue
            }
        }
    }

    /// A node named `name` of rank `rank` at `hz`, logging its ticks into `log` and
    /// stopping the run from `stop_at` on.
    pub(super) fn probe(
        (name, rank, hz): (&'static str, usize, f64),
        log: &Arc<Mutex<Vec<(u64, &'static str)>>>,
        stop_at: Option<Nanos>,
    ) -> GraphNode {
        let work = NodeOf::unbound(Probe {
            name,
            log: log.clone(),
            stop_at,
            last: Nanos::ZERO,
        });
        GraphNode::alone(name, NodeId(rank), Rate::new(hz).unwrap(), |_| work)
    }

    /// Actuator, sensor and policy at `hz` (sensor, policy, actuator), logging into `log`.
    pub(super) fn probes(
        log: &Arc<Mutex<Vec<(u64, &'static str)>>>,
        hz: [f64; 3],
    ) -> Vec<GraphNode> {
        // Deliberately listed out of priority order: the heap must sort by (due, priority).
        [
            ("actuator", 2, hz[2]),
            ("sensor", 0, hz[0]),
            ("policy", 1, hz[1]),
        ]
        .into_iter()
        .map(|node| probe(node, log, None))
        .collect()
    }
}

#[cfg(test)]
mod stop_flag_tests {
    use super::StopFlag;

    #[test]
    fn a_child_reads_its_parent_s_stop_and_keeps_its_own_to_itself() {
        let parent = StopFlag::new();
        let (a, b) = (parent.child(), parent.child());
        a.stop();
        assert!(a.is_stopped() && a.clone().is_stopped());
        assert!(
            !parent.is_stopped() && !b.is_stopped(),
            "a run's own stop stays its own"
        );
        let grandchild = b.child();
        parent.stop();
        assert!(
            b.is_stopped() && grandchild.is_stopped(),
            "Ctrl-C reaches every run"
        );
    }
}
