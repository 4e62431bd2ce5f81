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
//!   executor's nodes share its threads (`scheduler/shared.rs`). Message interleaving then
//!   depends on the OS scheduler, so two runs with the same seed are **not** reproducible:
//!   drop counts and latencies vary by a handful. That is the nature of concurrency, not a
//!   bug; use the virtual clock to compare runs.

use ratelab_core::clock::{Clock, MonotonicClock};
mod handover;
mod shared;
mod threads;
pub use threads::{check_real_clock_threads, plan_threads};
use threads::{none_started, not_started};

use ratelab_core::executor::{
    CallbackSpan, Dispatch, ExecFigures, ExecutionPlan, ExecutorFigures, ExecutorKind,
    NodeExecFigures,
};
use ratelab_core::metrics::{LatencyStats, NodeTiming};
use ratelab_core::node::{Flow, Node};
use ratelab_core::rate::{first_on_grid, next_deadline, DeadlineWaiter};
use ratelab_core::time::Nanos;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;

/// A shared stop request: set by a fall, Ctrl-C, the lab, or a failed node.
#[derive(Clone, Debug, Default)]
pub struct StopFlag(Arc<AtomicBool>);

impl StopFlag {
    /// A flag not yet set.
    pub fn new() -> Self {
        Self::default()
    }
    /// Ask every node loop to stop.
    pub fn stop(&self) {
        self.0.store(true, Ordering::SeqCst);
    }
    /// Has a stop been asked for?
    pub fn is_stopped(&self) -> bool {
        self.0.load(Ordering::SeqCst)
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

/// What running one virtual instant did.
#[derive(Debug, PartialEq)]
pub enum InstantOutcome {
    /// Every tick due at the instant ran; bit `i` of `ticked` is set when node `i` ticked.
    Ran {
        /// The nodes that ticked, as a bit set over node indices.
        ticked: u64,
    },
    /// A node stopped the graph (the fall).
    Stopped,
    /// A node panicked: the graph stops and the run names the node.
    Failed(EndReason),
}

/// One event of the virtual clock under the executors' rules
/// ([`VirtualScheduler::event_now`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// Node `node`'s tick has computed until `at`: its held outputs go out now.
    Publish {
        /// The node's index.
        node: usize,
        /// The run time, ns.
        at: Nanos,
    },
    /// Node `node` got a thread at `at`: its tick starts.
    Start {
        /// The node's index.
        node: usize,
        /// The run time, ns.
        at: Nanos,
    },
}

impl Event {
    /// The event's node and run time.
    pub fn node_at(&self) -> (usize, Nanos) {
        match *self {
            Event::Publish { node, at } | Event::Start { node, at } => (node, at),
        }
    }
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

/// The virtual-clock executor, steppable one instant at a time (the lab paces it against
/// the wall clock for display; pacing never changes the order of ticks). Every virtual run
/// (headless, sweep, replay, exercises, the lab) goes through [`VirtualScheduler::run_instant`].
///
/// It applies the [`ExecutionPlan`]'s rules ([`ratelab_core::executor`]) at virtual instants: at
/// each instant, first the ticks whose compute time ends then publish their outputs (in
/// rank order), then the timers due then are released, then every tick that can start
/// starts (in the executors' order; a tick with no compute time publishes at once, so a
/// node downstream at the same instant sees it, as in the chapter). With the default plan
/// (one thread per node, no compute time) this is exactly the chapter's `run_virtual`:
/// every node due at an instant ticks in tie-break order.
#[derive(Clone)]
pub struct VirtualScheduler {
    /// Armed timers: (next call, rank, node).
    releases: BinaryHeap<Reverse<(Nanos, u32, usize)>>,
    /// Ticks computing: (end, node).
    completions: BinaryHeap<Reverse<(Nanos, usize)>>,
    now: Nanos,
    ticks: Vec<u64>,
    ranks: Vec<u32>,
    dispatch: Dispatch,
    /// Each node's next call time (its timer's due time).
    next_call: Vec<Nanos>,
    /// The release (due time) of each node's running tick.
    running_release: Vec<Nanos>,
    /// The start of each node's running tick.
    running_start: Vec<Nanos>,
    /// Per node: what its executor measured (only when `track`).
    stats: Vec<NodeExecStats>,
    /// The ticks that ended since [`VirtualScheduler::take_spans`] last took them (only when
    /// `track`; at most [`ratelab_core::executor::MAX_SPANS`], the oldest dropped).
    spans: std::collections::VecDeque<CallbackSpan>,
    /// Told of every span as it ends (only when `track`).
    span_hook: Option<ratelab_core::executor::SpanHook>,
    /// A plan asked for while running (the lab's executor key), taken before each instant.
    plan_request: Option<PlanRequest>,
    /// Per node, a new grid for its ticks (its phase, run time) to take when its tick now
    /// released or running starts ([`VirtualScheduler::set_phase`]).
    regrid: Vec<Option<Nanos>>,
    /// An instant begun with [`VirtualScheduler::begin_instant`] whose events are still
    /// being drawn ([`VirtualScheduler::next_in_instant`]).
    instant_open: bool,
    /// Run time the graph spent under another clock ([`VirtualScheduler::take_over`]): the
    /// executors' figures span the virtual clock's time only.
    away: Nanos,
    track: bool,
    /// Any executor shares threads, or ticks take time: the executors' rules apply. Else
    /// (the default) an instant is the chapter's loop, which they reduce to.
    general: bool,
}

impl VirtualScheduler {
    /// Every node due at `t = 0`, on a thread of its own.
    pub fn new(nodes: &[Box<dyn Node>]) -> Self {
        Self::with_offsets(nodes, &[])
    }

    /// Node `i` first due at `offsets[i]` (missing offsets are 0), on a thread of its own.
    pub fn with_offsets(nodes: &[Box<dyn Node>], offsets: &[Nanos]) -> Self {
        let names: Vec<&str> = nodes.iter().map(|n| n.name()).collect();
        Self::with_plan(nodes, offsets, ExecutionPlan::per_node(&names), false)
    }

    /// Node `i` first due at `offsets[i]`, on the executors of `plan` (indexed like
    /// `nodes`). `track`: measure response times, skipped ticks and busy time
    /// ([`VirtualScheduler::figures`]), and ask every tick its compute time; without it and
    /// with one thread per node (the default: what [`VirtualScheduler::new`] and
    /// [`VirtualScheduler::with_offsets`] make) an instant is the chapter's loop, with no
    /// compute time asked and no bookkeeping.
    pub fn with_plan(
        nodes: &[Box<dyn Node>],
        offsets: &[Nanos],
        plan: ExecutionPlan,
        track: bool,
    ) -> Self {
        let next_call: Vec<Nanos> = (0..nodes.len())
            .map(|i| offsets.get(i).copied().unwrap_or(Nanos::ZERO))
            .collect();
        let ranks: Vec<u32> = nodes.iter().map(|n| n.priority()).collect();
        let plan_per_node = plan.is_per_node();
        let releases = nodes
            .iter()
            .enumerate()
            .map(|(i, n)| Reverse((next_call[i], n.priority(), i)))
            .collect();
        Self {
            releases,
            completions: BinaryHeap::new(),
            now: Nanos::ZERO,
            ticks: vec![0; nodes.len()],
            dispatch: Dispatch::new(plan, &ranks),
            ranks,
            next_call,
            running_release: vec![Nanos::ZERO; nodes.len()],
            running_start: vec![Nanos::ZERO; nodes.len()],
            stats: if track {
                vec![NodeExecStats::default(); nodes.len()]
            } else {
                Vec::new()
            },
            spans: std::collections::VecDeque::new(),
            span_hook: None,
            plan_request: None,
            regrid: vec![None; nodes.len()],
            instant_open: false,
            away: Nanos::ZERO,
            general: track || !plan_per_node,
            track,
        }
    }

    /// Take back the timers, running ticks, counters and plan of `saved` (a clone of this
    /// scheduler taken earlier, [`crate::runcore`]), keeping this one's span hook and plan
    /// request (wiring, not state).
    pub fn load(&mut self, saved: &VirtualScheduler) {
        let hook = self.span_hook.take();
        let request = self.plan_request.take();
        self.clone_from(saved);
        self.span_hook = hook;
        self.plan_request = request;
    }

    /// The time of the next event: a timer due or a tick's compute time ending.
    pub fn next_due(&self) -> Option<Nanos> {
        let release = self.releases.peek().map(|Reverse((due, _, _))| *due);
        let end = self.completions.peek().map(|Reverse((at, _))| *at);
        match (release, end) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// The due time of node `node`'s next tick (index in the graph), if it is scheduled.
    pub fn next_due_of(&self, node: usize) -> Option<Nanos> {
        self.next_call.get(node).copied()
    }

    /// The virtual time of the latest instant.
    pub fn now(&self) -> Nanos {
        self.now
    }

    /// Ticks run so far, per node index.
    pub fn ticks(&self) -> &[u64] {
        &self.ticks
    }

    /// What the executors measured, when tracking (else `None`): per node its response
    /// times, skipped ticks and busy time, per executor its utilization over `elapsed`
    /// (run time, less any the graph spent under another clock).
    pub fn figures(&self, elapsed: Nanos) -> Option<ExecFigures> {
        self.track.then(|| {
            // Ticks still computing have held their thread since they started.
            let mut stats = self.stats.clone();
            for (i, s) in stats.iter_mut().enumerate() {
                if self.dispatch.is_running(i) {
                    let held = elapsed.saturating_sub(self.running_start[i]);
                    s.busy = s.busy.saturating_add(held);
                }
            }
            figures(
                self.dispatch.plan(),
                &stats,
                elapsed.saturating_sub(self.away),
            )
        })
    }

    /// When measuring: the ticks that ended since the last call, oldest first (the lab's
    /// executor timeline); empty otherwise.
    pub fn take_spans(&mut self) -> Vec<CallbackSpan> {
        self.spans.drain(..).collect()
    }

    /// Run on `plan` from the next instant: the executors' rules apply from then on, and
    /// their figures are measured from then on when they were not before (see
    /// [`ratelab_core::executor::Dispatch::replan`]).
    pub fn set_plan(&mut self, plan: ExecutionPlan) {
        self.dispatch.replan(plan);
        self.general = true;
        if !self.track {
            self.track = true;
            self.stats = vec![NodeExecStats::default(); self.ticks.len()];
        }
    }

    /// Take a plan from `request` before each instant ([`VirtualScheduler::set_plan`]): how
    /// a command applied at an instant (the lab, a replay) changes the executors.
    pub fn take_plans_from(&mut self, request: PlanRequest) {
        self.plan_request = Some(request);
    }

    /// Put node `node`'s ticks on a new grid from the instant `from` on (the next instant,
    /// before which the change is applied), its rate unchanged (`period`, its period now):
    /// - a node that has ticked: its next tick is the first point of
    ///   `(phase mod period) + k·period` at or after `from`; if its tick is released but
    ///   waiting for a thread, it takes the grid when that tick starts (its next tick the
    ///   grid's first point after the start);
    /// - a node that has not ticked yet: its first tick is where its first deadline would be
    ///   with `phase` as its phase offset, `max(start, phase)` (`start`: when it joins the
    ///   graph, `start_ms`), moved onto `phase + k·period` at or after `from` once an instant
    ///   has run. Before any instant it is exactly the run started at that phase offset.
    pub fn set_phase(
        &mut self,
        node: usize,
        phase: Nanos,
        period: Nanos,
        from: Nanos,
        start: Nanos,
    ) {
        if node >= self.next_call.len() {
            return;
        }
        let ticked = self.ticks[node] > 0;
        let armed = self.releases.iter().any(|Reverse((_, _, i))| *i == node);
        let next = if ticked {
            let phase = Nanos(phase.0.checked_rem(period.0).unwrap_or(phase.0));
            if !armed {
                self.regrid[node] = Some(phase);
                return;
            }
            first_on_grid(phase, period, from)
        } else {
            let began = self.ticks.iter().any(|&t| t > 0);
            let after = if began { from } else { Nanos::ZERO };
            first_on_grid(phase, period, after).max(start)
        };
        if !armed {
            // Released before its first tick, waiting for a thread: it starts when it can.
            return;
        }
        self.releases.retain(|Reverse((_, _, i))| *i != node);
        self.next_call[node] = next;
        self.releases.push(Reverse((next, self.ranks[node], node)));
    }

    /// Tell `hook` of every tick as it ends (when measuring: executors or compute times).
    pub fn set_span_hook(&mut self, hook: ratelab_core::executor::SpanHook) {
        self.span_hook = Some(hook);
    }

    fn keep_span(&mut self, span: CallbackSpan) {
        if let Some(h) = &self.span_hook {
            h(&span);
        }
        if self.spans.len() == ratelab_core::executor::MAX_SPANS {
            self.spans.pop_front();
        }
        self.spans.push_back(span);
    }

    /// When measuring: each node's ticks and skipped ticks so far, by node index (cheap:
    /// what the lab shows live).
    pub fn skipped_ticks(&self) -> Option<Vec<(u64, u64)>> {
        self.track.then(|| {
            self.ticks
                .iter()
                .zip(&self.stats)
                .map(|(&t, s)| (t, s.skipped_ticks))
                .collect()
        })
    }

    /// Run the next tick. Returns its time, the node's index and the node's [`Flow`].
    /// A panic in the node propagates; [`VirtualScheduler::run_instant`] catches it.
    /// For the default plan only (one thread per node, no compute time);
    /// [`VirtualScheduler::run_instant`] applies any plan.
    fn tick_next(&mut self, nodes: &mut [Box<dyn Node>]) -> Option<(Nanos, usize, Flow)> {
        let Reverse((due, prio, i)) = self.releases.pop()?;
        self.now = due;
        self.ticks[i] += 1;
        let flow = nodes[i].tick(due);
        self.rearm(i, prio, due.saturating_add(nodes[i].rate().period()));
        Some((due, i, flow))
    }

    fn rearm(&mut self, node: usize, prio: u32, next: Nanos) {
        self.next_call[node] = next;
        self.releases.push(Reverse((next, prio, node)));
    }

    /// Run the next instant: the ends of ticks computing until then, the timers due then,
    /// every tick that can start then (see the type's docs). A node that panics is caught,
    /// named, and ends the graph ([`InstantOutcome::Failed`]).
    pub fn run_instant(&mut self, nodes: &mut [Box<dyn Node>]) -> InstantOutcome {
        self.instant_open = false;
        if !self.general {
            return self.run_plain_instant(nodes);
        }
        let Some(t) = self.next_due() else {
            return InstantOutcome::Ran { ticked: 0 };
        };
        self.now = t;
        let mut ticked = 0u64;
        while let Some(event) = self.event_now() {
            match event {
                Event::Publish { node, at } => nodes[node].publish_held(at),
                Event::Start { node, .. } => {
                    ticked |= 1 << (node % 64);
                    match self.start_here(nodes, node) {
                        Err(reason) => return InstantOutcome::Failed(reason),
                        Ok((Flow::Stop, _)) => return InstantOutcome::Stopped,
                        Ok((Flow::Continue, _)) => {}
                    }
                }
            }
        }
        InstantOutcome::Ran { ticked }
    }

    /// Move the clock on to the instant `t` (the next due time, [`VirtualScheduler::next_due`],
    /// which the caller has checked against its run's duration and before which it applied
    /// its commands): its events are then drawn one by one with
    /// [`VirtualScheduler::event_now`]. One instant of [`VirtualScheduler::run_instant`] is
    /// this, event by event; `ratelab::runcore::RunCore::next_event` drives it.
    pub fn begin_instant(&mut self, t: Nanos) {
        self.now = t;
        self.instant_open = true;
    }

    /// The next event of the instant begun with [`VirtualScheduler::begin_instant`]
    /// ([`VirtualScheduler::event_now`]); `None` when none is open or its events are all
    /// drawn (it is then closed: the caller makes the next one ready and begins it).
    pub fn next_in_instant(&mut self) -> Option<Event> {
        if !self.instant_open {
            return None;
        }
        let e = self.event_now();
        self.instant_open = e.is_some();
        e
    }

    /// The next event at the current instant under the executors' rules, or `None` when
    /// every event of the instant has been drawn (everything left is later: a compute time
    /// ends after its start, a timer is rearmed after its tick). First the ticks whose
    /// compute time ends now ([`Event::Publish`], in rank order), then every tick that can
    /// start ([`Event::Start`], in the executors' order), once the timers due now are
    /// released.
    ///
    /// The scheduler's side of the event is done when this returns (a thread freed, a
    /// thread taken); the node's side is the caller's: [`Node::publish_held`] for a publish
    /// where the node runs, and for a start exactly one of [`VirtualScheduler::start_here`]
    /// (the node ticks here) or [`VirtualScheduler::start_elsewhere`] (it ticks in another
    /// process, `ratelab::distributed::lockstep`), before the next call.
    pub fn event_now(&mut self) -> Option<Event> {
        let t = self.now;
        if let Some(&Reverse((at, i))) = self.completions.peek() {
            if at <= t {
                self.completions.pop();
                self.ended(i, self.running_release[i], self.running_start[i], at);
                return Some(Event::Publish { node: i, at });
            }
        }
        while let Some(&Reverse((at, _, i))) = self.releases.peek() {
            if at > t {
                break;
            }
            self.releases.pop();
            self.dispatch.release(i);
        }
        let i = self.dispatch.pick()?;
        self.dispatch.start(i);
        // Held from now: a tick taken but never run (the run ended first) holds its thread
        // for no time before `t` ([`VirtualScheduler::figures`]).
        self.running_release[i] = self.next_call[i];
        self.running_start[i] = t;
        Some(Event::Start { node: i, at: t })
    }

    /// Node `node`'s tick of the [`Event::Start`] just taken runs here: its compute time is
    /// drawn (its outputs held when it is not zero), it ticks, and its outputs go out now
    /// or when its compute time has elapsed. Returns the node's [`Flow`] and the compute
    /// time drawn.
    ///
    /// # Errors
    /// The node panicked: [`EndReason::NodeFailed`] naming it (the graph must stop).
    pub fn start_here(
        &mut self,
        nodes: &mut [Box<dyn Node>],
        node: usize,
    ) -> Result<(Flow, Nanos), EndReason> {
        let t = self.now;
        let n = &mut nodes[node];
        // The period as the tick starts (a rate change takes effect from the next tick).
        let period = n.rate().period();
        let result = catch_quietly(|| {
            let compute = n.compute_time();
            if compute.0 > 0 {
                n.hold_outputs();
            }
            (compute, n.tick(t))
        });
        match result {
            Ok((compute, flow)) => {
                self.started(node, period, compute);
                Ok((flow, compute))
            }
            Err(p) => {
                self.ticks[node] += 1; // it did start
                Err(EndReason::NodeFailed {
                    node: nodes[node].name().to_string(),
                    message: panic_message(&*p),
                })
            }
        }
    }

    /// Node `node`'s tick of the [`Event::Start`] just taken runs in another process and
    /// computes for `compute` (as that process reports it); `nodes[node]` gives its period
    /// only.
    pub fn start_elsewhere(&mut self, nodes: &[Box<dyn Node>], node: usize, compute: Nanos) {
        self.started(node, nodes[node].rate().period(), compute);
    }

    /// Node `i`'s tick, released at `release` and started at `start`, has published its
    /// outputs at `end`: its thread and group are free, and when measuring, its response
    /// time, busy time and span are kept.
    fn ended(&mut self, i: usize, release: Nanos, start: Nanos, end: Nanos) {
        self.dispatch.finish(i);
        if self.track {
            self.stats[i].record(release, end, end.saturating_sub(start));
            self.keep_span(CallbackSpan {
                node: i,
                release,
                start,
                end,
            });
        }
    }

    /// The bookkeeping of a tick started now: its count, its skipped periods, its end (now
    /// when it takes no time), its timer rearmed.
    fn started(&mut self, i: usize, period: Nanos, compute: Nanos) {
        let t = self.now;
        let release = self.next_call[i];
        let (next, skipped) = match self.regrid[i].take() {
            // A new grid (a phase change while this tick waited): its first point after now.
            Some(phase) => (first_on_grid(phase, period, t.saturating_add(Nanos(1))), 0),
            None => next_deadline(release, t, period),
        };
        self.ticks[i] += 1;
        if self.track {
            self.stats[i].skipped_ticks += skipped;
        }
        if compute.0 == 0 {
            self.ended(i, release, t, t);
        } else {
            self.completions
                .push(Reverse((t.saturating_add(compute), i)));
        }
        // Always after `t` (a zero period is refused by `Rate`).
        self.rearm(i, self.ranks[i], next);
    }

    /// An instant of the default plan: every node due ticks, in tie-break order (the
    /// executors' rules reduce to this when every node has a thread and ticks take no time).
    fn run_plain_instant(&mut self, nodes: &mut [Box<dyn Node>]) -> InstantOutcome {
        let Some(t) = self.next_due() else {
            return InstantOutcome::Ran { ticked: 0 };
        };
        let mut ticked = 0u64;
        while self.next_due() == Some(t) {
            let next = self.next_node().unwrap_or(0);
            match catch_quietly(|| self.tick_next(nodes)) {
                Err(p) => {
                    return InstantOutcome::Failed(EndReason::NodeFailed {
                        node: nodes[next].name().to_string(),
                        message: panic_message(&*p),
                    })
                }
                Ok(None) => break,
                Ok(Some((_, i, flow))) => {
                    ticked |= 1 << (i % 64);
                    if flow == Flow::Stop {
                        return InstantOutcome::Stopped;
                    }
                }
            }
        }
        InstantOutcome::Ran { ticked }
    }

    /// The index of the node whose timer is due next.
    pub fn next_node(&self) -> Option<usize> {
        self.releases.peek().map(|Reverse((_, _, i))| *i)
    }

    /// Run instant by instant until `duration` (ticks due at exactly `duration` run), a
    /// stop, a failed node, or the flag. `before_instant(t)` runs before every instant with
    /// its time. The scheduler's own tests' loop: a run drives the scheduler through
    /// `ratelab::runcore::RunCore`.
    #[cfg(test)]
    fn run(
        &mut self,
        nodes: &mut [Box<dyn Node>],
        duration: Nanos,
        stop: &StopFlag,
        before_instant: &mut dyn FnMut(Nanos),
    ) -> RunEnd {
        loop {
            if stop.is_stopped() {
                return RunEnd {
                    at: self.now,
                    reason: EndReason::Interrupted,
                };
            }
            match self.next_due() {
                Some(due) if due <= duration => {
                    before_instant(due);
                    let asked = self
                        .plan_request
                        .as_ref()
                        .and_then(|r| r.lock().unwrap_or_else(|e| e.into_inner()).take());
                    if let Some(plan) = asked {
                        self.set_plan(plan);
                    }
                }
                _ => {
                    return RunEnd {
                        at: duration,
                        reason: EndReason::Duration,
                    }
                }
            }
            match self.run_instant(nodes) {
                InstantOutcome::Ran { .. } => {}
                InstantOutcome::Stopped => {
                    return RunEnd {
                        at: self.now,
                        reason: EndReason::NodeStopped,
                    }
                }
                InstantOutcome::Failed(reason) => {
                    return RunEnd {
                        at: self.now,
                        reason,
                    }
                }
            }
        }
    }
}

/// One tick under the real clock, as a [`TickHook`] is told of it.
#[derive(Clone, Copy, Debug)]
pub struct TickReport<'a> {
    /// The node's index (its tie-break rank).
    pub node: usize,
    /// The node's name.
    pub name: &'a str,
    /// Run time the tick started.
    pub now: Nanos,
    /// Its lateness: actual start − scheduled.
    pub lateness: Nanos,
    /// Wall time the tick took, start to end (its compute time burned included; zero for
    /// a tick that panicked).
    pub took: Nanos,
}

/// Where a command leaves a plan for the virtual scheduler to take at its next instant
/// ([`VirtualScheduler::take_plans_from`]).
pub type PlanRequest = Arc<std::sync::Mutex<Option<ExecutionPlan>>>;

/// Called on the node's thread after each tick under the real clock ([`TickReport`]).
pub type TickHook = Arc<dyn Fn(&TickReport<'_>) + Send + Sync>;

/// Options of the real-clock executor.
#[derive(Clone)]
pub struct RealOptions {
    /// Spin (rather than sleep) this long before each deadline.
    pub spin_margin: Nanos,
    /// First deadline of node `i` (missing = 0): phase offsets between nodes.
    pub phase_offsets: Vec<Nanos>,
    /// Told about every tick (e.g. a recorder logging lateness).
    pub on_tick: Option<TickHook>,
    /// While set, no node ticks (the lab's pause); deadlines missed meanwhile are skipped.
    pub pause: Option<Arc<AtomicBool>>,
    /// Run every node thread under `SCHED_FIFO` at this priority (1..=99), if the kernel
    /// allows; a refusal is reported in [`NodeTiming::sched_error`] and the node runs on
    /// under its default policy. See [`ratelab_core::realtime`].
    ///
    /// One priority for all nodes, on purpose: ordering them by tie-break priority (sensor
    /// highest) was measured (BENCHMARKS.md) and moved all waiting for a core onto the
    /// actuator, whose spinning peers never yield to a lower priority.
    pub rt_priority: Option<u8>,
    /// The instant the run's time is zero (`None`: when [`run_real`] starts). Processes of
    /// one graph share it, so their stamps share one clock (`ratelab::distributed`).
    pub start: Option<std::time::Instant>,
    /// The run time the run starts at: 0, or the instant another clock reached when the run
    /// goes on from there (`ratelab::runcore::RunCore::run_real`). The executors' figures
    /// span from here to the end.
    pub from: Nanos,
    /// The executors ([`ratelab_core::executor`]); `None`: one thread per node.
    pub plan: Option<ExecutionPlan>,
    /// Measure response times, skipped ticks and busy time ([`RealRun::exec`]).
    pub track: bool,
}

impl Default for RealOptions {
    fn default() -> Self {
        Self {
            spin_margin: ratelab_core::rate::DEFAULT_SPIN_MARGIN,
            phase_offsets: Vec::new(),
            on_tick: None,
            pause: None,
            rt_priority: None,
            start: None,
            from: Nanos::ZERO,
            plan: None,
            track: false,
        }
    }
}

/// What [`run_real`] hands back.
pub struct RealRun {
    /// How it ended.
    pub end: RunEnd,
    /// Per-node tick timing, one per node run, in their order (a node whose thread died,
    /// panicking, has an empty one).
    pub timing: Vec<NodeTiming>,
    /// The nodes, returned for reuse or inspection (a node whose thread died is not).
    pub nodes: Vec<Box<dyn Node>>,
    /// What the executors measured, when [`RealOptions::track`] (and no node thread died).
    pub exec: Option<ExecFigures>,
}

/// This thread's CPU time (Linux `CLOCK_THREAD_CPUTIME_ID`).
fn thread_cpu_time() -> Nanos {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return Nanos::ZERO;
    }
    Nanos(ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64)
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

/// A node's figures at the end of a real-clock run: `ticks` ticked and `skipped` deadlines
/// skipped over `elapsed`, with their `lateness` and `cpu` of thread CPU time (the
/// scheduling policy left for the caller to fill in).
fn node_timing(
    node: String,
    ticks: u64,
    skipped: u64,
    lateness: &LatencyStats,
    cpu: Nanos,
    elapsed: Nanos,
) -> NodeTiming {
    let us = |n: Option<Nanos>| n.map_or(0.0, Nanos::as_micros_f64);
    NodeTiming {
        node,
        ticks,
        skipped,
        lateness_p50_us: us(lateness.quantile(0.5)),
        lateness_p99_us: us(lateness.quantile(0.99)),
        lateness_max_us: us(lateness.max()),
        cpu_ms: cpu.as_millis_f64(),
        measured_hz: if elapsed.0 > 0 {
            ticks as f64 / elapsed.as_secs_f64()
        } else {
            0.0
        },
        sched: String::new(),
        sched_error: None,
    }
}

/// Burn `cpu` of this thread's CPU time in a busy loop (`CLOCK_THREAD_CPUTIME_ID`): a tick's
/// declared compute time under the real clock. On a loaded machine it takes longer than
/// `cpu` of wall time, as real computation does. Stops early on `stop`.
fn burn(cpu: Nanos, stop: &StopFlag) {
    let wall = std::time::Instant::now();
    let t0 = thread_cpu_time();
    let mut x = 0u64;
    loop {
        for _ in 0..512 {
            x = std::hint::black_box(x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1));
        }
        // Without a thread CPU clock (it read 0), the wall clock measures.
        let spent = if t0.0 == 0 {
            Nanos(wall.elapsed().as_nanos() as u64)
        } else {
            thread_cpu_time().saturating_sub(t0)
        };
        if spent >= cpu || stop.is_stopped() {
            return;
        }
    }
}

/// One tick of `node` at `now` under the real clock, with its compute time: its outputs are
/// held while it burns that much CPU, then published at the clock's time. Returns the flow
/// and the time its outputs went out.
fn real_tick(
    node: &mut dyn Node,
    now: Nanos,
    clock: &MonotonicClock,
    stop: &StopFlag,
) -> (Flow, Nanos) {
    let compute = node.compute_time();
    if compute.0 == 0 {
        return (node.tick(now), clock.now());
    }
    node.hold_outputs();
    let flow = node.tick(now);
    burn(compute, stop);
    let done = clock.now();
    node.publish_held(done);
    (flow, done)
}

/// What a node's own thread gives back when it ends: the node, its timing, its executor
/// figures, and its panic's message if it panicked.
type OwnThreadEnd = (Box<dyn Node>, NodeTiming, NodeExecStats, Option<String>);

/// A node [`spawn_own_thread`] could not start: the node back (when it could be taken
/// back), and the machine's refusal.
type NotStarted = (Option<Box<dyn Node>>, std::io::Error);

/// Start node `i` on a thread of its own (a per-node executor): it ticks on its grid from
/// its phase offset until the run's end or `stop` (a pause holds it; a tick that says stop
/// records when in `stop_at` and stops the run; a panic stops the run). The thread keeps
/// Rust's default stack (2 MiB, or `RUST_MIN_STACK`): a Python callback or a brain may
/// need it.
///
/// # Errors
/// The node back with the machine's refusal, when the thread cannot be started (no more
/// threads, no memory for its stack).
fn spawn_own_thread(
    i: usize,
    node: Box<dyn Node>,
    opts: &RealOptions,
    (clock, waiter, duration): (MonotonicClock, DeadlineWaiter, Nanos),
    (stop, stop_at): (&StopFlag, &Arc<AtomicU64>),
) -> Result<std::thread::JoinHandle<OwnThreadEnd>, NotStarted> {
    let track = opts.track;
    let stop = stop.clone();
    let stop_at = stop_at.clone();
    let first = opts.phase_offsets.get(i).copied().unwrap_or(Nanos::ZERO);
    let name = node.name().to_string();
    let on_tick = opts.on_tick.clone();
    let pause = opts.pause.clone();
    let rt_priority = opts.rt_priority;
    // Handed over through a cell, so that a thread that cannot start gives the node back.
    let cell: Arc<std::sync::Mutex<Option<Box<dyn Node>>>> =
        Arc::new(std::sync::Mutex::new(Some(node)));
    let handed = cell.clone();
    let spawned = std::thread::Builder::new()
        .name(name.clone())
        .spawn(move || {
            let mut node = handed
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .take()
                .expect("a node is handed to its thread once");
            drop(handed);
            let sched_error = rt_priority
                .and_then(|p| ratelab_core::realtime::set_current_thread_fifo(p).err())
                .map(|e| e.to_string());
            let sched = ratelab_core::realtime::current_thread_sched().to_string();
            let cpu0 = thread_cpu_time();
            let mut lateness = LatencyStats::default();
            let mut exec = NodeExecStats::default();
            let (mut ticks, mut skipped) = (0u64, 0u64);
            let mut deadline = first;
            let result = catch_quietly(|| loop {
                // Wake for the deadline, the run's end or a stop, whichever is
                // first: a slow node must not sleep past either.
                waiter.wait_until_or(clock.instant_at(deadline.min(duration)), &|| {
                    stop.is_stopped()
                });
                let mut was_paused = false;
                while pause.as_ref().is_some_and(|p| p.load(Ordering::SeqCst)) && !stop.is_stopped()
                {
                    was_paused = true;
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
                let now = clock.now();
                if now >= duration || stop.is_stopped() {
                    break;
                }
                if was_paused {
                    // Back on the grid after a pause: the ticks missed are not late ticks.
                    let (next, _) = next_deadline(deadline, now, node.rate().period());
                    deadline = next;
                    continue;
                }
                let late = now.saturating_sub(deadline);
                lateness.record(late);
                ticks += 1;
                let (flow, done) = real_tick(&mut *node, now, &clock, &stop);
                if track {
                    exec.record(deadline, done, done.saturating_sub(now));
                }
                if let Some(hook) = &on_tick {
                    hook(&TickReport {
                        node: i,
                        name: &name,
                        now,
                        lateness: late,
                        took: done.saturating_sub(now),
                    });
                }
                if flow == Flow::Stop {
                    stop_at.fetch_min(now.0, Ordering::SeqCst);
                    stop.stop();
                    break;
                }
                let (next, missed) = next_deadline(deadline, clock.now(), node.rate().period());
                deadline = next;
                skipped += missed;
            });
            if result.is_err() {
                stop.stop();
            }
            exec.skipped_ticks = skipped;
            let elapsed = clock.now().min(duration).saturating_sub(first);
            let cpu = thread_cpu_time().saturating_sub(cpu0);
            let timing = NodeTiming {
                sched,
                sched_error,
                ..node_timing(name, ticks, skipped, &lateness, cpu, elapsed)
            };
            (node, timing, exec, result.err().map(|p| panic_message(&*p)))
        });
    spawned.map_err(|e| {
        let node = cell.lock().unwrap_or_else(|p| p.into_inner()).take();
        (node, e)
    })
}

/// Run `nodes` against a monotonic clock until `duration`, a node's [`Flow::Stop`] (which
/// stops every thread), or `stop`, on the executors of [`RealOptions::plan`]: by default one
/// OS thread per node, sleeping to absolute deadlines; a single- or multi-threaded executor's
/// nodes share its threads by [`ratelab_core::executor`]'s rules. Each tick's lateness (actual −
/// scheduled) is recorded for jitter statistics. A panicking node stops the graph and is
/// reported in [`EndReason::NodeFailed`].
///
/// Never more than [`ratelab_core::limits::MAX_REAL_CLOCK_THREADS`] threads ([`plan_threads`]): a
/// plan that needs more starts none and ends at once as the failure of the first node past
/// the bound ([`check_real_clock_threads`]'s line; a run's settings refuse such a graph
/// before it is built, `ratelab::config::RunConfig::validate`). A thread the machine will
/// not start (no more threads, no memory for its stack) stops the threads started, which
/// are joined, and ends the run as that node's failure: every node that did not run comes
/// back untouched.
pub fn run_real(
    nodes: Vec<Box<dyn Node>>,
    duration: Nanos,
    stop: &StopFlag,
    opts: &RealOptions,
) -> RealRun {
    let clock = opts
        .start
        .map_or_else(MonotonicClock::start, MonotonicClock::starting_at);
    let waiter = DeadlineWaiter::new(opts.spin_margin);
    let stop_at = Arc::new(AtomicU64::new(u64::MAX));
    let names: Vec<String> = nodes.iter().map(|n| n.name().to_string()).collect();
    let plan = opts.plan.clone().unwrap_or_else(|| {
        ExecutionPlan::per_node(&names.iter().map(String::as_str).collect::<Vec<_>>())
    });
    let track = opts.track;
    let own_thread: Vec<bool> = (0..nodes.len())
        .map(|i| plan.executors[plan.node_executor[i]].kind == ExecutorKind::PerNode)
        .collect();
    // More threads than the bound (a graph the run's settings did not check for the real
    // clock: the lab's switch of clocks): none starts, every node back.
    if let Err(line) = check_real_clock_threads(&plan) {
        return none_started(nodes, &names, &own_thread, line, clock.now().min(duration));
    }
    let mut slots: Vec<Option<shared::Finished>> = (0..names.len()).map(|_| None).collect();
    // A node that did not run comes back as it was, with no ticks.
    let unrun = |i: usize, node: Box<dyn Node>| -> shared::Finished {
        let timing = NodeTiming {
            node: names[i].clone(),
            ..NodeTiming::default()
        };
        (node, timing, NodeExecStats::default())
    };
    let mut shared_nodes: Vec<Option<Box<dyn Node>>> = Vec::new();
    let mut handles = Vec::new();
    // The first node whose thread the machine would not start, and why: the run stops
    // there (the threads started are stopped and joined), and ends as that node's failure.
    let mut refused: Option<(usize, String)> = None;
    for (i, node) in nodes.into_iter().enumerate() {
        if refused.is_some() {
            slots[i] = Some(unrun(i, node));
            shared_nodes.push(None);
            continue;
        }
        if !own_thread[i] {
            shared_nodes.push(Some(node));
            continue;
        }
        shared_nodes.push(None);
        match spawn_own_thread(i, node, opts, (clock, waiter, duration), (stop, &stop_at)) {
            Ok(handle) => handles.push((i, handle)),
            Err((node, e)) => {
                stop.stop();
                if let Some(node) = node {
                    slots[i] = Some(unrun(i, node));
                }
                refused = Some((i, not_started("its thread", &e)));
            }
        }
    }
    // Only when an executor shares threads (its bookkeeping holds a histogram per node),
    // and every node's own thread started.
    let shared = if refused.is_none() && own_thread.contains(&false) {
        Some(shared::SharedExecutors::start(
            shared_nodes,
            &plan,
            shared::Context {
                clock,
                duration,
                stop: stop.clone(),
                stop_at: stop_at.clone(),
                opts: opts.clone(),
            },
        ))
    } else {
        for (i, node) in shared_nodes.into_iter().enumerate() {
            if let Some(node) = node {
                slots[i] = Some(unrun(i, node));
            }
        }
        None
    };
    let mut failed = refused.map(|(i, message)| EndReason::NodeFailed {
        node: names[i].clone(),
        message,
    });
    for (i, h) in handles {
        match h.join() {
            Ok((node, t, exec, panic)) => {
                if let (Some(message), None) = (panic, &failed) {
                    failed = Some(EndReason::NodeFailed {
                        node: t.node.clone(),
                        message,
                    });
                }
                slots[i] = Some((node, t, exec));
            }
            Err(p) => {
                failed.get_or_insert(EndReason::NodeFailed {
                    node: names[i].clone(),
                    message: panic_message(&*p),
                });
            }
        }
    }
    if let Some(shared) = shared {
        let shared_end = shared.join();
        if let (Some((node, message)), None) = (shared_end.failed, &failed) {
            failed = Some(EndReason::NodeFailed { node, message });
        }
        for (i, s) in shared_end.nodes.into_iter().enumerate() {
            if let Some(s) = s {
                slots[i] = Some(s);
            }
        }
    }
    let (nodes, timing, stats) = gather(slots, &names);
    let end = real_end(
        failed,
        stop_at.load(Ordering::SeqCst),
        stop,
        clock.now().min(duration),
        duration,
    );
    let span = end.at.saturating_sub(opts.from);
    let exec = (track && stats.len() == names.len()).then(|| figures(&plan, &stats, span));
    RealRun {
        end,
        timing,
        nodes,
        exec,
    }
}

/// Every node's slot after a real-clock run, in the graph's order: the nodes that came
/// back, every node's timing and the figures of those that came back.
fn gather(
    slots: Vec<Option<shared::Finished>>,
    names: &[String],
) -> (Vec<Box<dyn Node>>, Vec<NodeTiming>, Vec<NodeExecStats>) {
    let mut nodes = Vec::new();
    let mut timing = Vec::new();
    let mut stats = Vec::new();
    for (i, slot) in slots.into_iter().enumerate() {
        match slot {
            Some((node, t, exec)) => {
                nodes.push(node);
                timing.push(t);
                stats.push(exec);
            }
            // Its thread died (the node panicked): no timing, but its place kept, so that
            // every later node's timing stays its own.
            None => timing.push(NodeTiming {
                node: names[i].clone(),
                ..NodeTiming::default()
            }),
        }
    }
    (nodes, timing, stats)
}

/// How a real-clock run ended: a node's failure first, then a node's stop at `stopped_at`
/// (`u64::MAX`: none), then `stop` (an interruption) at `now`, else its `duration`.
fn real_end(
    failed: Option<EndReason>,
    stopped_at: u64,
    stop: &StopFlag,
    now: Nanos,
    duration: Nanos,
) -> RunEnd {
    if let Some(reason) = failed {
        RunEnd { at: now, reason }
    } else if stopped_at != u64::MAX {
        RunEnd {
            at: Nanos(stopped_at),
            reason: EndReason::NodeStopped,
        }
    } else if stop.is_stopped() {
        RunEnd {
            at: now,
            reason: EndReason::Interrupted,
        }
    } else {
        RunEnd {
            at: duration,
            reason: EndReason::Duration,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::limits::MAX_REAL_CLOCK_THREADS;
    use ratelab_core::rate::Rate;
    use std::sync::Mutex;

    struct Probe {
        name: &'static str,
        prio: u32,
        rate: Rate,
        log: Arc<Mutex<Vec<(u64, &'static str)>>>,
        stop_at: Option<Nanos>,
    }

    impl Node for Probe {
        fn name(&self) -> &str {
            self.name
        }
        fn priority(&self) -> u32 {
            self.prio
        }
        fn rate(&self) -> &Rate {
            &self.rate
        }
        fn tick(&mut self, now: Nanos) -> Flow {
            self.log.lock().unwrap().push((now.0, self.name));
            if self.stop_at.is_some_and(|t| now >= t) {
                Flow::Stop
            } else {
                Flow::Continue
            }
        }
    }

    fn probes(log: &Arc<Mutex<Vec<(u64, &'static str)>>>, hz: [f64; 3]) -> Vec<Box<dyn Node>> {
        // Deliberately listed out of priority order: the heap must sort by (due, priority).
        [
            ("actuator", 2, hz[2]),
            ("sensor", 0, hz[0]),
            ("policy", 1, hz[1]),
        ]
        .into_iter()
        .map(|(name, prio, hz)| {
            Box::new(Probe {
                name,
                prio,
                rate: Rate::new(hz).unwrap(),
                log: log.clone(),
                stop_at: None,
            }) as Box<dyn Node>
        })
        .collect()
    }

    #[test]
    fn ties_break_by_priority_and_duration_is_inclusive() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 10.0, 50.0]);
        let end = VirtualScheduler::new(&nodes).run(
            &mut nodes,
            Nanos::SECOND,
            &StopFlag::new(),
            &mut |_| {},
        );
        assert_eq!(end.reason, EndReason::Duration);
        let log = log.lock().unwrap();
        assert_eq!(&log[..3], &[(0, "sensor"), (0, "policy"), (0, "actuator")]);
        // At t = 100 ms both the 50 Hz sensor and the 10 Hz policy are due: exact tie.
        let at_100: Vec<_> = log
            .iter()
            .filter(|(t, _)| *t == 100_000_000)
            .map(|(_, n)| *n)
            .collect();
        assert_eq!(at_100, vec!["sensor", "policy", "actuator"]);
        assert_eq!(log.iter().filter(|(_, n)| *n == "actuator").count(), 51);
        assert_eq!(log.last().unwrap().0, 1_000_000_000);
    }

    #[test]
    fn a_stop_halts_the_world() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 50.0, 50.0]);
        let sensor = Box::new(Probe {
            name: "sensor",
            prio: 0,
            rate: Rate::new(50.0).unwrap(),
            log: log.clone(),
            stop_at: Some(Nanos(40_000_000)),
        });
        nodes[1] = sensor;
        let end = VirtualScheduler::new(&nodes).run(
            &mut nodes,
            Nanos::SECOND,
            &StopFlag::new(),
            &mut |_| {},
        );
        assert_eq!(
            end,
            RunEnd {
                at: Nanos(40_000_000),
                reason: EndReason::NodeStopped
            }
        );
        assert_eq!(log.lock().unwrap().last(), Some(&(40_000_000, "sensor")));
    }

    #[test]
    fn a_panicking_node_under_the_virtual_clock_is_named_not_fatal() {
        struct Flaky(Rate, &'static str, bool);
        impl Node for Flaky {
            fn name(&self) -> &str {
                self.1
            }
            fn priority(&self) -> u32 {
                u32::from(self.2)
            }
            fn rate(&self) -> &Rate {
                &self.0
            }
            fn tick(&mut self, now: Nanos) -> Flow {
                assert!(!(self.2 && now > Nanos::ZERO), "policy exploded");
                Flow::Continue
            }
        }
        let nodes = || -> Vec<Box<dyn Node>> {
            vec![
                Box::new(Flaky(Rate::new(50.0).unwrap(), "sensor", false)),
                Box::new(Flaky(Rate::new(50.0).unwrap(), "policy", true)),
            ]
        };
        let mut n = nodes();
        let mut sched = VirtualScheduler::new(&n);
        assert_eq!(
            sched.run_instant(&mut n),
            InstantOutcome::Ran { ticked: 0b11 }
        );
        match sched.run_instant(&mut n) {
            InstantOutcome::Failed(EndReason::NodeFailed { node, message }) => {
                assert_eq!(node, "policy");
                assert!(message.contains("policy exploded"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        // The whole-run path reports the same instead of unwinding through the caller.
        let mut n = nodes();
        let end =
            VirtualScheduler::new(&n).run(&mut n, Nanos::SECOND, &StopFlag::new(), &mut |_| {});
        assert_eq!(end.at, Nanos(20_000_000));
        assert!(matches!(end.reason, EndReason::NodeFailed { ref node, .. } if node == "policy"));
    }

    #[test]
    fn the_slowest_rate_never_overflows_run_time() {
        // 1e-300 Hz: a period past u64 nanoseconds, saturated to "never".
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 1e-300, 50.0]);
        let mut sched = VirtualScheduler::new(&nodes);
        let end = sched.run(&mut nodes, Nanos::SECOND, &StopFlag::new(), &mut |_| {});
        assert_eq!(end.reason, EndReason::Duration);
        let policy_ticks = log
            .lock()
            .unwrap()
            .iter()
            .filter(|(_, n)| *n == "policy")
            .count();
        assert_eq!(policy_ticks, 1, "ticks once at 0, next due never");
    }

    /// A node that logs its starts and the ends of its held ticks, with a compute time.
    struct Worker {
        name: &'static str,
        rate: Rate,
        compute: Nanos,
        log: WorkLog,
    }

    impl Node for Worker {
        fn name(&self) -> &str {
            self.name
        }
        fn priority(&self) -> u32 {
            0
        }
        fn rate(&self) -> &Rate {
            &self.rate
        }
        fn tick(&mut self, now: Nanos) -> Flow {
            self.log
                .lock()
                .unwrap()
                .push((now.0 / 1_000_000, self.name, "start"));
            Flow::Continue
        }
        fn compute_time(&mut self) -> Nanos {
            self.compute
        }
        fn publish_held(&mut self, at: Nanos) {
            self.log
                .lock()
                .unwrap()
                .push((at.0 / 1_000_000, self.name, "end"));
        }
    }

    type WorkLog = Arc<Mutex<Vec<(u64, &'static str, &'static str)>>>;

    /// Sensor and policy at 50 Hz, the policy computing `policy_ms`, on `plan`, for 100 ms.
    fn two_workers(plan: ExecutionPlan, policy_ms: u64) -> (WorkLog, VirtualScheduler, RunEnd) {
        let log: WorkLog = Arc::new(Mutex::new(Vec::new()));
        let mut nodes: Vec<Box<dyn Node>> = [("sensor", 0), ("policy", policy_ms)]
            .into_iter()
            .map(|(name, ms)| {
                Box::new(Worker {
                    name,
                    rate: Rate::new(50.0).unwrap(),
                    compute: Nanos::from_millis(ms),
                    log: log.clone(),
                }) as Box<dyn Node>
            })
            .collect();
        let mut sched = VirtualScheduler::with_plan(&nodes, &[], plan, true);
        let end = sched.run(
            &mut nodes,
            Nanos::from_millis(100),
            &StopFlag::new(),
            &mut |_| {},
        );
        (log, sched, end)
    }

    fn starts(log: &WorkLog, name: &str) -> Vec<u64> {
        log.lock()
            .unwrap()
            .iter()
            .filter(|(_, n, what)| *n == name && *what == "start")
            .map(|(t, _, _)| *t)
            .collect()
    }

    #[test]
    fn a_compute_time_publishes_late_and_a_long_one_skips_periods_on_the_grid() {
        let (log, sched, _) = two_workers(ExecutionPlan::per_node(&["sensor", "policy"]), 30);
        // Own threads: the sensor is untouched; the policy (30 ms per 20 ms period) starts
        // when its thread is free, on its grid: 0, 30 (due 20), 60 (due 40: 60 skipped),
        // 90 (due 80).
        assert_eq!(starts(&log, "sensor"), vec![0, 20, 40, 60, 80, 100]);
        assert_eq!(starts(&log, "policy"), vec![0, 30, 60, 90]);
        let ends: Vec<u64> = log
            .lock()
            .unwrap()
            .iter()
            .filter(|(_, n, w)| *n == "policy" && *w == "end")
            .map(|(t, _, _)| *t)
            .collect();
        assert_eq!(ends, vec![30, 60, 90], "outputs 30 ms after each start");
        let f = sched.figures(Nanos::from_millis(100)).unwrap();
        assert_eq!(f.nodes[1].skipped_ticks, 1);
        assert_eq!(f.nodes[0].skipped_ticks, 0);
        assert_eq!(f.nodes[0].response_time_max_ms, 0.0);
        // Releases 0, 20, 40 answered at 30, 60, 90: 30, 40, 50 ms.
        assert!(
            (f.nodes[1].response_time_max_ms - 50.0).abs() < 0.1,
            "{f:?}"
        );
    }

    #[test]
    fn one_slow_callback_on_a_single_threaded_executor_starves_the_timer_beside_it() {
        let plan = ExecutionPlan::one_executor(
            &["sensor", "policy"],
            ratelab_core::executor::ExecutorKind::SingleThreaded,
            1,
        );
        let (log, sched, _) = two_workers(plan, 30);
        // The sensor waits for the policy's 30 ms each time: 0, 30, 60, 90 (late ticks, one
        // period skipped at 60), never its own 20 ms grid.
        assert_eq!(starts(&log, "sensor"), vec![0, 30, 60, 90]);
        assert_eq!(starts(&log, "policy"), vec![0, 30, 60, 90]);
        let f = sched.figures(Nanos::from_millis(100)).unwrap();
        assert_eq!(f.nodes[0].skipped_ticks, 1);
        assert!(
            (f.nodes[0].response_time_max_ms - 20.0).abs() < 0.01,
            "{f:?}"
        );
        assert!((f.executors[0].utilization - 1.0).abs() < 1e-9, "{f:?}");
        // Twice the same: the virtual clock models the executor exactly.
        let plan = ExecutionPlan::one_executor(
            &["sensor", "policy"],
            ratelab_core::executor::ExecutorKind::SingleThreaded,
            1,
        );
        let (again, _, _) = two_workers(plan, 30);
        assert_eq!(*log.lock().unwrap(), *again.lock().unwrap());
    }

    #[test]
    fn the_executors_rules_reduce_to_the_chapters_loop_by_default() {
        // One thread per node and no compute time: the general engine (measuring) and the
        // chapter's loop tick the same nodes at the same instants in the same order.
        for hz in [
            [50.0, 50.0, 50.0],
            [50.0, 7.0, 50.0],
            [200.0, 33.0, 50.0],
            [3.0, 1000.0, 50.0],
        ] {
            let runs: Vec<Vec<(u64, &'static str)>> = [false, true]
                .into_iter()
                .map(|track| {
                    let log = Arc::new(Mutex::new(Vec::new()));
                    let mut nodes = probes(&log, hz);
                    let names: Vec<&str> = nodes.iter().map(|n| n.name()).collect();
                    let plan = ExecutionPlan::per_node(&names);
                    let offsets = [Nanos(0), Nanos(3_000_000), Nanos(1)];
                    let mut sched = VirtualScheduler::with_plan(&nodes, &offsets, plan, track);
                    let end = sched.run(
                        &mut nodes,
                        Nanos::from_millis(2000),
                        &StopFlag::new(),
                        &mut |_| {},
                    );
                    assert_eq!(end.reason, EndReason::Duration);
                    let out = log.lock().unwrap().clone();
                    out
                })
                .collect();
            assert!(runs[0].len() > 10);
            assert_eq!(runs[0], runs[1], "{hz:?}");
        }
    }

    #[test]
    fn two_threads_give_the_sensor_its_grid_back() {
        let plan = ExecutionPlan::one_executor(
            &["sensor", "policy"],
            ratelab_core::executor::ExecutorKind::MultiThreaded,
            2,
        );
        let (log, _, _) = two_workers(plan, 30);
        assert_eq!(starts(&log, "sensor"), vec![0, 20, 40, 60, 80, 100]);
        assert_eq!(starts(&log, "policy"), vec![0, 30, 60, 90]);
    }

    #[test]
    fn rate_change_applies_from_next_tick() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, 50.0, 50.0]);
        let policy_rate = nodes[2].rate().clone();
        let mut sched = VirtualScheduler::new(&nodes);
        let end = sched.run(&mut nodes, Nanos(300_000_000), &StopFlag::new(), &mut |t| {
            if t == Nanos(40_000_000) {
                policy_rate.set_hz(10.0).unwrap();
            }
        });
        assert_eq!(end.reason, EndReason::Duration);
        let policy: Vec<u64> = log
            .lock()
            .unwrap()
            .iter()
            .filter(|(_, n)| *n == "policy")
            .map(|(t, _)| t / 1_000_000)
            .collect();
        // Ticks at 0, 20, then 40 (already scheduled) runs and schedules 40 + 100 = 140.
        assert_eq!(policy, vec![0, 20, 40, 140, 240]);
    }

    #[test]
    fn real_clock_runs_every_node_and_reports_panics() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let nodes = probes(&log, [100.0, 100.0, 100.0]);
        let run = run_real(
            nodes,
            Nanos::from_millis(100),
            &StopFlag::new(),
            &RealOptions::default(),
        );
        assert_eq!(run.end.reason, EndReason::Duration);
        assert_eq!(run.timing.len(), 3);
        assert!(run.timing.iter().all(|t| t.ticks >= 5), "{:?}", run.timing);

        struct Boom(Rate);
        impl Node for Boom {
            fn name(&self) -> &str {
                "boom"
            }
            fn priority(&self) -> u32 {
                0
            }
            fn rate(&self) -> &Rate {
                &self.0
            }
            fn tick(&mut self, _: Nanos) -> Flow {
                panic!("sensor cable unplugged")
            }
        }
        // The failed node first: the nodes after it keep their own timing.
        let mut nodes: Vec<Box<dyn Node>> = vec![Box::new(Boom(Rate::new(50.0).unwrap()))];
        nodes.extend(probes(&log, [100.0, 100.0, 100.0]));
        let run = run_real(
            nodes,
            Nanos::SECOND,
            &StopFlag::new(),
            &RealOptions::default(),
        );
        assert_eq!(
            run.end.reason,
            EndReason::NodeFailed {
                node: "boom".into(),
                message: "sensor cable unplugged".into()
            }
        );
        let named: Vec<&str> = run.timing.iter().map(|t| t.node.as_str()).collect();
        assert_eq!(named, ["boom", "actuator", "sensor", "policy"]);
    }

    /// A node that never ticks (a real-clock run that starts no thread never calls it).
    struct Idle(String, Rate);
    impl Node for Idle {
        fn name(&self) -> &str {
            &self.0
        }
        fn priority(&self) -> u32 {
            0
        }
        fn rate(&self) -> &Rate {
            &self.1
        }
        fn tick(&mut self, _: Nanos) -> Flow {
            Flow::Continue
        }
    }

    #[test]
    fn the_threads_a_plan_starts_are_counted_before_any_starts() {
        let names: Vec<String> = (0..10).map(|i| format!("n{i}")).collect();
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        assert_eq!(plan_threads(&ExecutionPlan::per_node(&names)), 10);
        let single = ExecutionPlan::one_executor(&names, ExecutorKind::SingleThreaded, 1);
        assert_eq!(plan_threads(&single), 1);
        let pool = ExecutionPlan::one_executor(&names, ExecutorKind::MultiThreaded, 4);
        assert_eq!(plan_threads(&pool), 4);
        assert_eq!(check_real_clock_threads(&pool), Ok(()));
        // One past the bound, one thread per node: refused in one line naming it.
        let many: Vec<String> = (0..=MAX_REAL_CLOCK_THREADS)
            .map(|i| format!("n{i}"))
            .collect();
        let many: Vec<&str> = many.iter().map(String::as_str).collect();
        let line = check_real_clock_threads(&ExecutionPlan::per_node(&many)).unwrap_err();
        assert_eq!(line.lines().count(), 1);
        assert!(
            line.starts_with("the real clock would start 1025 threads (one per node on a thread of its own, and each shared executor's), at most 1024: run it under the virtual clock (--clock virtual), or share threads among its nodes (--executor single_threaded"),
            "{line}"
        );
        assert!(
            line.ends_with("(ratelab::limits::MAX_REAL_CLOCK_THREADS)"),
            "{line}"
        );
        // The same nodes on one shared thread are well within it.
        let shared = ExecutionPlan::one_executor(&many, ExecutorKind::SingleThreaded, 1);
        assert_eq!(check_real_clock_threads(&shared), Ok(()));
    }

    #[test]
    fn a_real_clock_run_past_the_thread_bound_starts_none_and_gives_every_node_back() {
        let nodes: Vec<Box<dyn Node>> = (0..=MAX_REAL_CLOCK_THREADS)
            .map(|i| Box::new(Idle(format!("n{i}"), Rate::new(10.0).unwrap())) as Box<dyn Node>)
            .collect();
        let stop = StopFlag::new();
        let run = run_real(nodes, Nanos::SECOND, &stop, &RealOptions::default());
        match &run.end.reason {
            EndReason::NodeFailed { node, message } => {
                assert_eq!(node, &format!("n{MAX_REAL_CLOCK_THREADS}"));
                assert!(message.contains("MAX_REAL_CLOCK_THREADS"), "{message}");
            }
            other => panic!("ended as {other:?}"),
        }
        assert!(run.end.at < Nanos::SECOND, "{:?}", run.end);
        assert_eq!(run.nodes.len(), MAX_REAL_CLOCK_THREADS + 1);
        assert_eq!(run.timing.len(), MAX_REAL_CLOCK_THREADS + 1);
        assert!(run.timing.iter().all(|t| t.ticks == 0));
        assert!(!stop.is_stopped(), "nothing started, nothing to stop");
    }

    #[test]
    fn a_thread_the_machine_refuses_reads_as_one_line() {
        let e = std::io::Error::from_raw_os_error(libc::EAGAIN);
        let line = not_started("its thread", &e);
        assert_eq!(line.lines().count(), 1);
        assert!(
            line.starts_with("its thread could not be started ("),
            "{line}"
        );
        assert!(line.contains("--clock virtual"), "{line}");
        assert!(
            line.ends_with("ratelab::limits::MAX_REAL_CLOCK_THREADS)"),
            "{line}"
        );
    }
}
