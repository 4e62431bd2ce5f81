//! The virtual clock ([`VirtualScheduler`]): the chapter's discrete-event loop (ch2.8,
//! `run_virtual`) under the executors' rules, one instant or one event at a time, with
//! exact integer time and ties broken by priority then index (see [`super`]).

use super::*;

mod handover;

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

pub use ratelab_core::executor::PlanRequest;

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
    pub fn new(nodes: &[GraphNode]) -> Self {
        Self::with_offsets(nodes, &[])
    }

    /// Node `i` first due at `offsets[i]` (missing offsets are 0), on a thread of its own.
    pub fn with_offsets(nodes: &[GraphNode], offsets: &[Nanos]) -> Self {
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
        nodes: &[GraphNode],
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
    fn tick_next(&mut self, nodes: &mut [GraphNode]) -> Option<(Nanos, usize, Flow)> {
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
    pub fn run_instant(&mut self, nodes: &mut [GraphNode]) -> InstantOutcome {
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
    /// thread taken); the node's side is the caller's:
    /// [`GraphNode::publish_held`](crate::graph::nodes::GraphNode::publish_held) for a
    /// publish where the node runs, and for a start exactly one of
    /// [`VirtualScheduler::start_here`] (the node ticks here) or
    /// [`VirtualScheduler::start_elsewhere`] (it ticks in another process,
    /// `ratelab::distributed::lockstep`), before the next call.
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
        nodes: &mut [GraphNode],
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
    pub fn start_elsewhere(&mut self, nodes: &[GraphNode], node: usize, compute: Nanos) {
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
    fn run_plain_instant(&mut self, nodes: &mut [GraphNode]) -> InstantOutcome {
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
        nodes: &mut [GraphNode],
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::kind::NodeOf;
    use crate::scheduler::probes::{probe, probes};
    use ratelab_core::ids::NodeId;
    use ratelab_core::ports::RustNode;
    use ratelab_core::publisher::Outbox;
    use ratelab_core::rate::Rate;
    use ratelab_core::topic::Subscription;
    use std::sync::Mutex;

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
        let sensor = probe(("sensor", 0, 50.0), &log, Some(Nanos(40_000_000)));
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
        /// Its tick panics after the first when it is the policy.
        struct Flaky(bool);
        impl RustNode for Flaky {
            type Input = ();
            type Output = ();
            fn tick(&mut self, now: Nanos, _: ()) {
                assert!(!(self.0 && now > Nanos::ZERO), "policy exploded");
            }
        }
        let nodes = || -> Vec<GraphNode> {
            [("sensor", false), ("policy", true)]
                .into_iter()
                .enumerate()
                .map(|(i, (name, fails))| {
                    let rate = Rate::new(50.0).unwrap();
                    GraphNode::alone(name, NodeId(i), rate, |_| NodeOf::unbound(Flaky(fails)))
                })
                .collect()
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
        // The slowest rate a run takes: one tick in the longest run (slower is refused,
        // `ratelab_core::rate::MIN_HZ`), its next deadline past this run's end.
        let log = Arc::new(Mutex::new(Vec::new()));
        let mut nodes = probes(&log, [50.0, ratelab_core::rate::MIN_HZ, 50.0]);
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

    /// A node that logs its starts, and the ends of its held ticks (what it publishes
    /// through its outbox while held, on a topic that logs each message as it goes out).
    struct Worker {
        name: &'static str,
        log: WorkLog,
        outbox: Outbox,
        topic: Arc<Subscription<()>>,
    }

    impl RustNode for Worker {
        type Input = ();
        type Output = ();
        fn tick(&mut self, now: Nanos, _: ()) {
            self.log
                .lock()
                .unwrap()
                .push((now.0 / 1_000_000, self.name, "start"));
            if self.outbox.is_holding() {
                self.outbox.publish(&self.topic, (), now, None);
            }
        }
    }

    type WorkLog = Arc<Mutex<Vec<(u64, &'static str, &'static str)>>>;

    /// Sensor and policy at 50 Hz, the policy computing `policy_ms`, on `plan`, for 100 ms.
    fn two_workers(plan: ExecutionPlan, policy_ms: u64) -> (WorkLog, VirtualScheduler, RunEnd) {
        let log: WorkLog = Arc::new(Mutex::new(Vec::new()));
        let mut nodes: Vec<GraphNode> = [("sensor", 0), ("policy", policy_ms)]
            .into_iter()
            .enumerate()
            .map(|(i, (name, ms))| {
                let topic = Arc::new(Subscription::new(name, 1).unwrap());
                let ends = log.clone();
                topic.add_tap(Box::new(move |m| {
                    ends.lock()
                        .unwrap()
                        .push((m.stamp.0 / 1_000_000, name, "end"));
                }));
                let rate = Rate::new(50.0).unwrap();
                let log = log.clone();
                let mut node = GraphNode::alone(name, NodeId(i), rate, |outbox| {
                    NodeOf::unbound(Worker {
                        name,
                        log,
                        outbox: outbox.clone(),
                        topic,
                    })
                });
                if ms > 0 {
                    node.set_compute(Nanos::from_millis(ms));
                }
                node
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
}
