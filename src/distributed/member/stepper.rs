//! One process's part of the virtual clock's run ([`crate::distributed::lockstep`]), as a
//! state machine advanced wherever what it waits for comes in: on Zenoh's receive thread
//! when another process's tick reports or an input sample arrive, on the process's main
//! thread when the launcher moves the horizon on (or every 100 ms, to notice an input that
//! never came).
//!
//! So an instant's path has no hand-off between threads: the thread that receives the
//! message a tick waits for runs the tick, publishes its samples and sends its report. And
//! a process sends the reports of its consecutive events together, in one message, when it
//! must next wait ([`wire::encode_reports`]): the chapter's graph split in two costs one
//! sample and one report message a hop.

use super::{held_topics, read_counters, Share};
use crate::distributed::lockstep::{check_tick_report, TickInbox};
use crate::distributed::wire::{self, Ticked};
use crate::distributed::{DistError, REPLY_TIMEOUT};
use crate::graph::spec::GraphSpec;
use crate::graph::TopicId;
use crate::node::{Flow, Node};
use crate::run::GraphState;
use crate::scheduler::{EndReason, Event, StopFlag, VirtualScheduler};
use crate::time::Nanos;
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Instant;
use zenoh::Wait;

/// The longest failure message a report carries, chars (a node's panic text may be long;
/// a message of reports is bounded, [`wire::decode_reports`]).
const MAX_FAILED_CHARS: usize = 2_000;

/// What one process's lockstep shares between Zenoh's callbacks and its main thread,
/// behind one lock: the other processes' reports (they may come before the run is set up
/// here) and the run, once set up.
pub(super) struct Slot {
    spec: GraphSpec,
    inbox: TickInbox,
    run: Option<Stepper>,
    /// Why the run cannot go on here (taken by the main thread).
    error: Option<DistError>,
}

/// A [`Slot`] as the callbacks and the main thread hold it.
pub(super) type SharedSlot = Arc<Mutex<Slot>>;

impl Slot {
    /// An empty slot for a run of `spec`: reports are kept until the run is set up.
    pub(super) fn shared(spec: GraphSpec) -> SharedSlot {
        Arc::new(Mutex::new(Slot {
            spec,
            inbox: TickInbox::new(),
            run: None,
            error: None,
        }))
    }

    /// Take in other processes' reports (decoded, from their keys), then advance.
    pub(super) fn reports(&mut self, ms: Vec<Ticked>) {
        for m in ms {
            if let Err(e) = self.inbox.accept(m, &self.spec) {
                self.error.get_or_insert(e);
                return;
            }
        }
        self.wake();
    }

    /// Advance the run as far as what has come in lets it (nothing before it is set up,
    /// or after it failed).
    pub(super) fn wake(&mut self) {
        if self.error.is_some() {
            return;
        }
        if let Some(run) = &mut self.run {
            if let Err(e) = run.advance(&mut self.inbox) {
                self.error = Some(e);
            }
        }
    }
}

/// The events of the run's one order, replayed here: this process's run in their turn,
/// the others' taken from their reports.
pub(super) struct Stepper {
    nodes: Vec<Box<dyn Node>>,
    sched: VirtualScheduler,
    share: Arc<Share>,
    /// The topics whose counters this process holds.
    held: Vec<TopicId>,
    /// Its nodes' indices in the graph.
    local: Vec<usize>,
    /// The newest seq each topic's remote publisher sent, from its reports.
    sent: Vec<Option<u64>>,
    /// The next event's place in the run's order.
    index: u64,
    /// The next event, once drawn from the scheduler and until it has run.
    next: Option<Event>,
    /// How far the launcher lets the run go, ns.
    horizon_ns: Option<u64>,
    /// No more events here: the run is over for this process (its last event, a stop or a
    /// failure), or the launcher ended it.
    done: bool,
    /// The input message the next event waits for, and since when.
    awaiting: Option<(TopicId, u64, Instant)>,
    /// Reports of this process's events not yet sent.
    outbox: Vec<Ticked>,
    /// Where its reports go ([`crate::distributed::Keys::ticked`]).
    publisher: zenoh::pubsub::Publisher<'static>,
    stop: StopFlag,
}

impl Stepper {
    /// The run of `nodes` (the whole graph's, this process's built) as `share` sets it up,
    /// its reports sent on `publisher`; it runs nothing before the first horizon.
    pub(super) fn new(
        nodes: Vec<Box<dyn Node>>,
        share: Arc<Share>,
        publisher: zenoh::pubsub::Publisher<'static>,
        stop: StopFlag,
    ) -> Self {
        // The whole graph's plan, as in one process: every process replays every executor.
        let sched = crate::run::virtual_scheduler(&share.cfg, &nodes);
        let held = held_topics(&share.cfg.graph, &share.mine);
        Stepper {
            nodes,
            sched,
            held,
            local: share.local(),
            sent: vec![None; share.cfg.graph.topics.len()],
            index: 0,
            next: None,
            horizon_ns: None,
            done: false,
            awaiting: None,
            outbox: Vec::new(),
            publisher,
            stop,
            share,
        }
    }

    /// The launcher lets the run go up to run time `until_ns`.
    pub(super) fn horizon(&mut self, until_ns: u64) {
        self.horizon_ns = Some(self.horizon_ns.unwrap_or(0).max(until_ns));
    }

    /// The launcher ended the run: nothing more runs here.
    pub(super) fn end(&mut self) {
        self.done = true;
    }

    /// The figures at run time `at`, once the last messages sent here have arrived: the
    /// graph's executors' figures as in one process (every process replayed every one).
    pub(super) fn capture(&self, at: Nanos) -> GraphState {
        let ticks: Vec<u64> = (self.share.ticks.iter())
            .map(|t| t.load(Ordering::Relaxed))
            .collect();
        let mut state = GraphState::capture(&self.share.handles, at, &ticks, None);
        state.exec = self.sched.figures(at);
        state
    }

    /// Run every event whose turn has come and whose inputs are here, then send the
    /// reports of this process's events among them.
    fn advance(&mut self, inbox: &mut TickInbox) -> Result<(), DistError> {
        let ran = self.run_events(inbox);
        self.flush()?;
        ran
    }

    fn run_events(&mut self, inbox: &mut TickInbox) -> Result<(), DistError> {
        let share = self.share.clone();
        let spec = &share.cfg.graph;
        while !self.done {
            if self.stop.is_stopped() {
                return Err(DistError::Peer("interrupted".into()));
            }
            let event = match self.next {
                Some(e) => e,
                None => match self.sched.next_event_until(share.cfg.duration) {
                    Some(e) => *self.next.insert(e),
                    None => {
                        self.done = true;
                        break;
                    }
                },
            };
            let (i, t) = event.node_at();
            if self.horizon_ns.is_none_or(|h| h < t.0) {
                break;
            }
            let over = if self.local.contains(&i) {
                match self.run_here(event)? {
                    Some(over) => over,
                    None => break, // an input message is still on its way
                }
            } else {
                let Some(m) = inbox.take(self.index) else {
                    break;
                };
                let compute =
                    check_tick_report(&m, self.index, event, spec).map_err(DistError::Peer)?;
                for &(topic, seq) in &m.published {
                    // Only a topic the node publishes (a report is untrusted input).
                    if spec.nodes[i].publishes.contains(&TopicId(topic)) {
                        self.sent[topic] = Some(seq);
                    }
                }
                if let Event::Start { .. } = event {
                    self.sched.start_elsewhere(&self.nodes, i, compute);
                }
                m.stop || m.failed.is_some()
            };
            self.next = None;
            self.index += 1;
            self.done = over;
            if self.outbox.len() >= wire::MAX_TICKS_PER_MESSAGE {
                self.flush()?;
            }
        }
        Ok(())
    }

    /// Run `event`, this process's, and keep its report: `Some(over)` (the node stopped the
    /// run or failed), or `None` while an input message it must see is still on its way
    /// (a start sees exactly the messages it would see in one process). An input that does
    /// not come within [`REPLY_TIMEOUT`] fails the tick.
    fn run_here(&mut self, event: Event) -> Result<Option<bool>, DistError> {
        let share = self.share.clone();
        let spec = &share.cfg.graph;
        let (i, t) = event.node_at();
        let mut failed = None;
        let mut flow = Flow::Continue;
        let mut compute = Nanos::ZERO;
        match event {
            Event::Publish { .. } => self.nodes[i].publish_held(t),
            Event::Start { .. } => {
                let inputs = spec.nodes[i].subscribes.iter();
                for &input in inputs.filter(|t| share.inbound.contains(t)) {
                    let Some(seq) = self.sent[input.0] else {
                        continue;
                    };
                    if share.arrivals.has(input, seq) {
                        continue;
                    }
                    let since = match self.awaiting {
                        Some((topic, s, since)) if topic == input && s == seq => since,
                        _ => self.awaiting.insert((input, seq, Instant::now())).2,
                    };
                    if since.elapsed() < REPLY_TIMEOUT {
                        return Ok(None);
                    }
                    failed = Some(format!(
                        "message {seq} on {} did not arrive within {} s",
                        spec.topic(input).name,
                        REPLY_TIMEOUT.as_secs()
                    ));
                    break;
                }
                self.awaiting = None;
                if failed.is_none() {
                    match self.sched.start_here(&mut self.nodes, i) {
                        Ok((f, c)) => (flow, compute) = (f, c),
                        Err(EndReason::NodeFailed { message, .. }) => failed = Some(message),
                        Err(other) => failed = Some(other.to_string()),
                    }
                } else {
                    self.sched.start_elsewhere(&self.nodes, i, Nanos::ZERO);
                }
                share.ticks[i].fetch_add(1, Ordering::Relaxed);
            }
        }
        share.run_time.fetch_max(t.0, Ordering::Relaxed);
        let published = if failed.is_none() {
            (share.forward_after)(i)
        } else {
            Vec::new()
        };
        let read = read_counters(&self.held, &share.handles);
        crate::graph::lock(&share.batch).keep(t.0, &read);
        let over = flow == Flow::Stop || failed.is_some();
        self.outbox.push(Ticked {
            process: share.process.clone(),
            index: self.index,
            node: i,
            t_ns: t.0,
            stop: flow == Flow::Stop,
            published,
            failed: failed.map(|m| m.chars().take(MAX_FAILED_CHARS).collect()),
            publish: matches!(event, Event::Publish { .. }),
            compute_ns: compute.0,
        });
        Ok(Some(over))
    }

    /// Send the reports kept, in one message.
    fn flush(&mut self) -> Result<(), DistError> {
        if self.outbox.is_empty() {
            return Ok(());
        }
        let bytes = wire::encode_reports(&self.outbox);
        self.outbox.clear();
        self.publisher.put(bytes).wait()?;
        Ok(())
    }
}

/// Run this process's part of the virtual clock's run: set up `nodes` in `slot` (whose
/// callbacks advance it as reports and samples arrive), move the horizon on as the
/// launcher's messages on `ctl` say, and at its stop wait for the last messages sent here
/// and return the figures.
///
/// # Errors
/// [`DistError::Peer`] when the run cannot go on here (another process out of step, an
/// input that never came, a report that cannot be sent), on `stop`, or when the launcher
/// goes.
pub(super) fn run_lockstep(
    nodes: Vec<Box<dyn Node>>,
    share: &Arc<Share>,
    slot: &SharedSlot,
    ctl: &crossbeam_channel::Receiver<crate::distributed::wire::ToMember>,
    publisher: zenoh::pubsub::Publisher<'static>,
    stop: &StopFlag,
    launcher_gone: &StopFlag,
) -> Result<GraphState, DistError> {
    use crate::distributed::wire::ToMember;
    use crossbeam_channel::RecvTimeoutError;
    {
        let mut s = crate::graph::lock(slot);
        s.run = Some(Stepper::new(nodes, share.clone(), publisher, stop.clone()));
        s.wake();
    }
    // Out of the slot, the callbacks leave the run alone.
    let take = || crate::graph::lock(slot).run.take();
    let (at_ns, need) = loop {
        if let Some(e) = crate::graph::lock(slot).error.take() {
            take();
            return Err(e);
        }
        if stop.is_stopped() {
            take();
            return Err(DistError::Peer("interrupted".into()));
        }
        match ctl.recv_timeout(std::time::Duration::from_millis(100)) {
            Ok(ToMember::Horizon { until_ns }) => {
                let mut s = crate::graph::lock(slot);
                if let Some(run) = &mut s.run {
                    run.horizon(until_ns);
                }
                s.wake();
            }
            Ok(ToMember::Stop { at_ns, need }) => break (at_ns, need),
            Ok(_) => {}
            Err(RecvTimeoutError::Timeout) if launcher_gone.is_stopped() => {
                take();
                return Err(DistError::Peer("the launcher went away".into()));
            }
            // An input that never came fails its tick after a while: look again.
            Err(RecvTimeoutError::Timeout) => crate::graph::lock(slot).wake(),
            Err(RecvTimeoutError::Disconnected) => {
                take();
                return Err(DistError::Peer("the launcher's channel closed".into()));
            }
        }
    };
    let Some(mut run) = take() else {
        return Err(DistError::Peer("the run was not set up".into()));
    };
    run.end();
    // The last messages sent to us are delivered before the counters are read.
    let spec = &share.cfg.graph;
    for (t, seq) in need {
        let t = TopicId(t);
        if share.inbound.contains(&t) && !share.arrivals.wait_for(t, seq, stop) {
            return Err(DistError::Peer(format!(
                "message {seq} on {} did not arrive before the end",
                spec.topic(t).name
            )));
        }
    }
    Ok(run.capture(Nanos(at_ns)))
}
