//! One process's part of the virtual clock's run ([`crate::lockstep`]): its graph in a run
//! core, drawn event by event ([`RunCore::next_event`]), its own nodes' events run here
//! ([`RunCore::run_event`]) and the others' taken from their reports
//! ([`RunCore::ran_elsewhere`]), which the launcher hands on: the one drive loop
//! ([`drive`]) taking events, whose event source here is [`Advance`]. A state machine advanced
//! wherever what it waits for comes in: on Zenoh's receive thread when other processes'
//! tick reports or an input sample arrive, on the process's main thread when the launcher
//! moves the horizon on (or every 100 ms, to notice an input that never came). At the end
//! it takes the reports of every event of the run before it reports
//! ([`crate::wire::ToProcess::Events`]).
//!
//! So an instant's path has no hand-off between threads: the thread that receives the
//! message a tick waits for runs the tick, publishes its samples and sends its report. And
//! a process sends the reports of its consecutive events together, in one message, when it
//! must next wait ([`wire::encode_reports`]): the chapter's graph split in two costs one
//! sample and one report message a hop in a star, and, linked directly, one sample that
//! carries its tick's reports ([`crate::lockstep::reports_ride_on_samples`]).

use super::stats::{held_topics, read_counters};
use super::Share;
use crate::liveliness::TokenWatch;
use crate::lockstep::{self, check_tick_report, TickInbox};
use crate::wire::ToProcess;
use crate::wire::{self, Ticked};
use crate::{DistError, REPLY_TIMEOUT};
use crossbeam_channel::{Receiver, Sender};
use ratelab_core::node::Flow;
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::graph::TopicId;
use ratelab_runtime::runcore::drive::{drive, Cursor, DrivePolicy, Drove, Events, Taken, Turn};
use ratelab_runtime::runcore::RunCore;
use ratelab_runtime::scheduler::{EndReason, Event, StopFlag};
use ratelab_runtime::summary::GraphState;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, TryLockError};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// The longest tick a Zenoh callback runs itself, ns: a node whose last tick here took
/// longer (or that has not ticked here yet) ticks on the main thread. A tick on Zenoh's one
/// thread holds up everything Zenoh does for the process (its keep-alives too: a tick of
/// Zenoh's lease, [`crate::LinkTimings`], would end the link), so only ticks known to be short
/// run there.
const CALLBACK_TICK_NS: u64 = 2_000_000;

/// The longest failure message a report carries, bytes (a node's panic text may be long;
/// a message of reports is bounded, [`wire::decode_reports`]): within the room of one
/// report, as a report with a longer one could not be read before.
const MAX_FAILED_BYTES: usize = wire::MAX_TICK_BYTES - 512;

/// The longest a report waits for the next one to go with it: past this it goes alone, so
/// slow ticks in a row report as they end, as the launcher's patience counts per report (in
/// a launch linked directly, per batch: a tick that may be long sends the launcher what it
/// holds first, `Advance::take`).
const MAX_REPORT_WAIT: Duration = Duration::from_millis(10);

/// What one process's lockstep shares between Zenoh's callbacks and its main thread: the
/// other processes' reports (they may come before the run is set up here) and the run, once
/// set up.
///
/// One thread advances the run at a time. A callback that finds it taken leaves its news
/// (a report in the inbox, an arrival, `dirty`) to the thread advancing, which looks again
/// before it lets go: a callback never waits for the main thread, which may be waiting for
/// Zenoh's one thread to send (its held-back samples, [`super::Spill`]).
pub(super) struct Slot {
    pub(super) spec: GraphSpec,
    inbox: Mutex<TickInbox>,
    run: Mutex<Option<Stepper>>,
    /// News came while another thread advanced the run.
    dirty: AtomicBool,
    /// Why the run cannot go on here (taken by the main thread).
    error: Mutex<Option<DistError>>,
    /// Tells the main thread to go on where a callback stopped (samples held back).
    nudge: Sender<()>,
}

/// A [`Slot`] as the callbacks and the main thread hold it.
pub(super) type SharedSlot = Arc<Slot>;

impl Slot {
    /// An empty slot for a run of `spec`: reports are kept until the run is set up. The
    /// receiver hears when the main thread must go on ([`run_lockstep`]).
    pub(super) fn shared(spec: GraphSpec) -> (SharedSlot, Receiver<()>) {
        let (nudge, nudged) = crossbeam_channel::bounded(1);
        let slot = Arc::new(Slot {
            spec,
            inbox: Mutex::new(TickInbox::new()),
            run: Mutex::new(None),
            dirty: AtomicBool::new(false),
            error: Mutex::new(None),
            nudge,
        });
        (slot, nudged)
    }

    /// Take in other processes' reports (decoded, from their keys), then advance (on
    /// Zenoh's receive thread).
    pub(super) fn reports(&self, ms: Vec<Ticked>) {
        if self.take_in(ms) {
            self.wake(false);
        }
    }

    /// Take in other processes' reports without advancing: `false` when one is refused
    /// (the run cannot go on here: the error is kept for the main thread).
    pub(super) fn take_in(&self, ms: Vec<Ticked>) -> bool {
        let mut inbox = ratelab_runtime::graph::lock(&self.inbox);
        for m in ms {
            if let Err(e) = inbox.accept(m, &self.spec) {
                ratelab_runtime::graph::lock(&self.error).get_or_insert(e);
                return false;
            }
        }
        true
    }

    /// Advance the run as far as what has come in lets it (nothing before it is set up, or
    /// after it failed): `on_main`, from the process's main thread (it waits its turn and
    /// puts any samples held back), else from a Zenoh callback (it leaves the run to the
    /// thread advancing it, and puts at most [`super::CALLBACK_SEND_BUDGET`] bytes itself).
    pub(super) fn wake(&self, on_main: bool) {
        self.dirty.store(true, Ordering::SeqCst);
        loop {
            let mut run = if on_main {
                ratelab_runtime::graph::lock(&self.run)
            } else {
                match self.run.try_lock() {
                    Ok(g) => g,
                    Err(TryLockError::Poisoned(p)) => p.into_inner(),
                    Err(TryLockError::WouldBlock) => return, // its holder sees `dirty`
                }
            };
            self.dirty.store(false, Ordering::SeqCst);
            if let Some(r) = run.as_mut() {
                if ratelab_runtime::graph::lock(&self.error).is_none() {
                    match r.advance(&self.inbox, on_main) {
                        Ok(false) => {}
                        Ok(true) => {
                            let _ = self.nudge.try_send(());
                        }
                        Err(e) => *ratelab_runtime::graph::lock(&self.error) = Some(e),
                    }
                }
            }
            drop(run);
            if !self.dirty.load(Ordering::SeqCst) {
                return;
            }
        }
    }

    /// Why the run cannot go on, if it cannot.
    fn take_error(&self) -> Option<DistError> {
        ratelab_runtime::graph::lock(&self.error).take()
    }

    /// Take the run out: the callbacks leave it alone from now on.
    fn take_run(&self) -> Option<Stepper> {
        ratelab_runtime::graph::lock(&self.run).take()
    }
}

/// The events of the run's one order, replayed here: this process's run in their turn,
/// the others' taken from their reports.
pub(super) struct Stepper {
    /// The graph (the whole graph's, this process's nodes run here), drawn event by event
    /// on the whole graph's plan, as in one process: every process replays every executor.
    core: RunCore,
    /// Where the run's order stands ([`Stepper::last`] sets its limit).
    cursor: Cursor<Event>,
    /// No more events here: the run is over for this process (its last event, a stop or a
    /// failure), or the launcher ended it.
    done: bool,
    turns: Turns,
}

/// What decides an event's turn here and takes it ([`Advance`], the lockstep's
/// [`DrivePolicy`]): the horizon, this process's nodes and their inputs, the others'
/// reports, and the reports this process sends.
struct Turns {
    share: Arc<Share>,
    /// The topics whose counters this process holds.
    held: Vec<TopicId>,
    /// Its nodes' indices in the graph.
    local: Vec<usize>,
    /// The newest seq each topic's remote publisher sent, from its reports.
    sent: Vec<Option<u64>>,
    /// How far the launcher lets the run go, and, linked directly, the reports kept for it.
    horizon: Horizon,
    /// The input message the next event waits for, and since when.
    awaiting: Option<(TopicId, u64, Instant)>,
    /// Reports of this process's events not yet sent.
    outbox: Vec<Ticked>,
    /// Per node, how long its last tick here took, ns (`None`: it has not ticked here).
    tick_ns: Vec<Option<u64>>,
    /// Ticks may run in a Zenoh callback at all (not under `--ros2`: a ROS 2 node's tick
    /// waits on Zenoh, and the ROS 2 bridge's tap on its thread).
    callback_ticks: bool,
    /// When the oldest report in `outbox` was kept.
    kept_at: Option<Instant>,
    /// Where its reports go ([`crate::Keys::ticked`]).
    publisher: zenoh::pubsub::Publisher<'static>,
    /// Linked directly: where the launcher's copy of its reports goes, in batches
    /// ([`Horizon::followed`]).
    progress: Option<zenoh::pubsub::Publisher<'static>>,
    stop: StopFlag,
}

/// Where a process's tick reports go under the virtual clock, and where its ticks run.
pub(super) struct Reporting {
    /// Every report, as it is made, to whoever follows this process's ticks
    /// ([`crate::Keys::ticked`]: in a star the launcher, which hands them on; linked
    /// directly, the other processes, but between two processes the reports of a tick that
    /// published a crossing sample ride on it instead,
    /// [`crate::lockstep::reports_ride_on_samples`]).
    pub ticked: zenoh::pubsub::Publisher<'static>,
    /// Linked directly: the launcher's copy, in batches ([`crate::Keys::progress`],
    /// [`crate::lockstep::follow_at`]).
    pub progress: Option<zenoh::pubsub::Publisher<'static>>,
    /// Ticks may run in a Zenoh callback at all (not under `--ros2`).
    pub callback_ticks: bool,
}

impl Reporting {
    /// Process `process`'s publishers of its reports on `session` (`direct`: linked
    /// directly, the launcher's copy too), its ticks allowed in Zenoh's callbacks.
    ///
    /// # Errors
    /// [`DistError::Zenoh`] when a publisher cannot be declared.
    pub(super) fn declare(
        session: &zenoh::Session,
        keys: &crate::Keys,
        process: &str,
        direct: bool,
    ) -> Result<Self, DistError> {
        // Never dropped under congestion (Zenoh's default drops): a lost report would stall
        // the run.
        let declare = |key: String| {
            session
                .declare_publisher(key)
                .congestion_control(zenoh::qos::CongestionControl::Block)
                .wait()
        };
        Ok(Reporting {
            ticked: declare(keys.ticked(process))?,
            progress: if direct {
                Some(declare(keys.progress(process))?)
            } else {
                None
            },
            callback_ticks: true,
        })
    }
}

/// How far the launcher lets a process's run go, and, linked directly, what the launcher
/// wants to hear of it: one place decides both from the events the run looks at, so the
/// reports kept for the launcher go once the run passes the time it named
/// ([`lockstep::follow_at`]) and never wait for the horizon itself.
#[derive(Debug, Default)]
struct Horizon {
    /// The latest run time the launcher lets the run reach, ns (`None`: it has not yet).
    until_ns: Option<u64>,
    /// The last event looked at lay past the horizon: the run waits for the launcher here.
    waits: bool,
    /// Linked directly: the reports sent to the other processes and not yet to the
    /// launcher (`None` in a star, where the launcher hands every report on as it comes).
    followed: Option<FollowedBatch>,
}

impl Horizon {
    /// No horizon yet; `direct`: linked directly, the launcher's copy of the reports kept.
    fn new(direct: bool) -> Self {
        Horizon {
            followed: direct.then(FollowedBatch::default),
            ..Horizon::default()
        }
    }

    /// The launcher lets the run go up to run time `until_ns` and names `follow_at_ns`
    /// ([`Stepper::horizon`]); an older horizon than the one held, overtaken, is ignored.
    fn moved(&mut self, until_ns: u64, follow_at_ns: Option<u64>) {
        if self.until_ns.is_some_and(|h| h >= until_ns) {
            return;
        }
        self.until_ns = Some(until_ns);
        if let Some(b) = self.followed.as_mut() {
            b.follow_from(follow_at_ns);
        }
    }

    /// The run here looks at its next event, at run time `at_ns`: whether the horizon lets
    /// it be taken (else the run waits for the launcher here, [`Horizon::waits`]). What the
    /// run looks at is what tells the reports kept when they are due
    /// ([`FollowedBatch::reached`]).
    fn admits(&mut self, at_ns: u64) -> bool {
        if let Some(b) = self.followed.as_mut() {
            b.look(at_ns);
        }
        let admitted = self.until_ns.is_some_and(|h| h >= at_ns);
        if !admitted {
            self.waits = true;
        }
        admitted
    }
}

/// The reports a process keeps for the launcher to follow ([`lockstep::follow_at`]): when
/// they are due, and the messages they make.
#[derive(Debug, Default)]
struct FollowedBatch {
    kept: Vec<Ticked>,
    /// When the oldest of `kept` was kept.
    since: Option<Instant>,
    /// The run time past which the launcher wants what is kept, as its newest horizon named
    /// it ([`lockstep::follow_at`]; `None` once the run here has passed it and sent).
    follow_at_ns: Option<u64>,
    /// The launcher names a time to send from: batches of [`lockstep::FOLLOWED_BATCH`]
    /// only where it does not.
    named: bool,
    /// The run time of the latest event the run here has looked at, ns: every event at an
    /// earlier time is taken (the drive loop looks at events in the run's order, each until
    /// it is taken).
    looked_ns: u64,
}

impl FollowedBatch {
    /// Keep `reports` (emptied), sent to the other processes just now.
    fn keep(&mut self, reports: &mut Vec<Ticked>) {
        if !reports.is_empty() {
            self.since.get_or_insert_with(Instant::now);
            self.kept.append(reports);
        }
    }

    /// The launcher's newest horizon names run time `follow_at_ns` to send from (`None`: it
    /// names none).
    fn follow_from(&mut self, follow_at_ns: Option<u64>) {
        self.follow_at_ns = follow_at_ns;
        self.named = follow_at_ns.is_some();
    }

    /// The run here looks at an event at run time `at_ns`.
    fn look(&mut self, at_ns: u64) {
        self.looked_ns = self.looked_ns.max(at_ns);
    }

    /// Whether the run here has gone past where the launcher wants to hear from it: it
    /// has looked at an event after run time [`FollowedBatch::follow_at_ns`], so every
    /// report the launcher needs from it to get there is made.
    fn reached(&self) -> bool {
        self.follow_at_ns.is_some_and(|at| self.looked_ns > at)
    }

    /// Whether what is kept is due to the launcher: any report when the run waits for the
    /// horizon or is over here (`waiting`), once the run here has passed where the launcher
    /// wants to hear from it ([`FollowedBatch::reached`]), or kept for
    /// [`lockstep::FOLLOWED_MAX_AGE`]; where the launcher names no such time, once
    /// [`lockstep::FOLLOWED_BATCH`] are kept.
    fn due(&self, waiting: bool) -> bool {
        let overdue = (self.since).is_some_and(|t| t.elapsed() >= lockstep::FOLLOWED_MAX_AGE);
        let full = !self.named && self.kept.len() >= lockstep::FOLLOWED_BATCH;
        !self.kept.is_empty() && (waiting || overdue || full || self.reached())
    }

    /// What is due ([`FollowedBatch::due`]), as messages of at most
    /// [`wire::MAX_TICKS_PER_MESSAGE`] reports each, in order; nothing is kept after. Once
    /// the run here has passed the launcher's time, whatever it sent (nothing, when it had
    /// sent everything just before), nothing more is due for that time: the next horizon
    /// names another.
    fn take_due(&mut self, waiting: bool) -> Vec<Vec<u8>> {
        let due = self.due(waiting);
        if self.reached() {
            self.follow_at_ns = None;
        }
        if !due {
            return Vec::new();
        }
        let messages = (self.kept.chunks(wire::MAX_TICKS_PER_MESSAGE))
            .map(wire::encode_reports)
            .collect();
        self.kept.clear();
        self.since = None;
        messages
    }
}

impl Stepper {
    /// The run of `core`'s graph (the whole graph's, this process's built) as `share` sets
    /// it up, its reports sent as `reporting` says; it runs nothing before the first
    /// horizon. With [`Reporting::callback_ticks`] false every event of this process runs
    /// on its main thread.
    pub(super) fn new(
        core: RunCore,
        share: Arc<Share>,
        reporting: Reporting,
        stop: StopFlag,
    ) -> Self {
        let Reporting {
            ticked: publisher,
            progress,
            callback_ticks,
        } = reporting;
        let held = held_topics(&share.cfg.graph, &share.mine);
        let turns = Turns {
            held,
            local: share.local(),
            sent: vec![None; share.cfg.graph.topics.len()],
            horizon: Horizon::new(progress.is_some()),
            awaiting: None,
            outbox: Vec::new(),
            tick_ns: vec![None; share.cfg.graph.nodes.len()],
            callback_ticks,
            kept_at: None,
            publisher,
            progress,
            stop,
            share,
        };
        Stepper {
            core,
            cursor: Cursor::default(),
            done: false,
            turns,
        }
    }

    /// The launcher lets the run go up to run time `until_ns` and, linked directly, wants
    /// the reports kept for it once the run passes `follow_at_ns` ([`lockstep::follow_at`]).
    pub(super) fn horizon(&mut self, until_ns: u64, follow_at_ns: Option<u64>) {
        self.turns.horizon.moved(until_ns, follow_at_ns);
    }

    /// The launcher ended the run: nothing more runs here.
    pub(super) fn end(&mut self) {
        self.done = true;
    }

    /// The run had `events` events (the launcher's word at its end): take the reports of
    /// every one before it, run nothing at or past it.
    pub(super) fn last(&mut self, events: u64) {
        self.cursor.limit = Some(events);
    }

    /// The events of the run still to take here before it reports (0 without the
    /// launcher's word, or once the run is over here).
    fn left(&self) -> u64 {
        if self.done {
            0
        } else {
            self.cursor.left()
        }
    }

    /// The figures at run time `at`, once the last messages sent here have arrived: the
    /// graph's executors' figures as in one process (every process replayed every one).
    pub(super) fn capture(&self, at: Nanos) -> GraphState {
        let share = &self.turns.share;
        let ticks: Vec<u64> = (share.ticks.iter())
            .map(|t| t.load(Ordering::Relaxed))
            .collect();
        let mut state = GraphState::capture(&share.handles, at, &ticks, None);
        state.exec = self.core.scheduler().figures(at);
        state
    }

    /// Run every event whose turn has come and whose inputs are here, then send the
    /// reports of this process's events among them. `on_main`: first put the samples held
    /// back, and put every sample as it is published (or keep it to carry its reports,
    /// [`super::Spill::carrying`]); else (on Zenoh's receive thread) stop
    /// after an event whose samples went past [`super::CALLBACK_SEND_BUDGET`], or before a
    /// tick not known to be short ([`CALLBACK_TICK_NS`]), and return `true`: the main
    /// thread must go on (putting the held-back samples and then the reports).
    fn advance(&mut self, inbox: &Mutex<TickInbox>, on_main: bool) -> Result<bool, DistError> {
        let spill = self.turns.share.bridge.spill.clone();
        if on_main {
            spill.set_budget(None);
            self.turns.share.bridge.put_held()?;
        } else if !spill.is_empty() {
            return Ok(true);
        } else {
            spill.set_budget(Some(super::CALLBACK_SEND_BUDGET));
        }
        let ran = self.run_events(inbox, on_main);
        if !spill.is_empty() {
            // The reports follow their samples: both from the main thread.
            return ran.map(|_| true);
        }
        self.turns.flush()?;
        // The launcher follows in batches: before the run waits for it to move the
        // horizon, and at the run's end here, it has every report made.
        let waiting = self.turns.horizon.waits || self.done || self.cursor.limit.is_some();
        self.turns.send_followed(waiting)?;
        ran
    }

    /// Run events as [`Stepper::advance`] says, through the drive loop ([`drive`]); `true`
    /// when a callback (`on_main` false) stopped before an event that is the main thread's
    /// to run.
    fn run_events(&mut self, inbox: &Mutex<TickInbox>, on_main: bool) -> Result<bool, DistError> {
        if self.done {
            return Ok(false);
        }
        self.turns.horizon.waits = false;
        let stop = self.turns.stop.clone();
        let mut turn = Advance {
            turns: &mut self.turns,
            inbox,
            on_main,
            to_main: false,
        };
        match drive(
            &mut Events(&mut self.core),
            &mut self.cursor,
            &mut turn,
            Some(&stop),
            None,
        )? {
            Drove::Waiting => Ok(turn.to_main),
            Drove::Over | Drove::Ended(_) | Drove::Exhausted => {
                self.done = true;
                Ok(false)
            }
            Drove::Limit => Ok(false), // the run's last event is taken
            Drove::Stopped => Err(DistError::Peer("interrupted".into())),
            Drove::Left => Ok(false), // never: this policy takes no intake
        }
    }
}

/// One advance of the lockstep ([`Stepper::advance`]) as the drive loop's event source:
/// an event's turn comes when the horizon reaches it (and, on a Zenoh callback, when it is
/// not a tick for the main thread); this process's events run here, the others' are taken
/// from their reports.
struct Advance<'a> {
    turns: &'a mut Turns,
    inbox: &'a Mutex<TickInbox>,
    on_main: bool,
    /// A callback stopped before an event that is the main thread's to run.
    to_main: bool,
}

impl<'c> DrivePolicy<Event, Events<'c>> for Advance<'_> {
    type Error = DistError;

    fn turn(&mut self, _index: u64, event: Event) -> Result<Turn, DistError> {
        let t = &mut *self.turns;
        let (i, at) = event.node_at();
        if !t.horizon.admits(at.0) {
            return Ok(Turn::Wait);
        }
        if t.outbox.len() >= wire::MAX_TICKS_PER_MESSAGE {
            t.flush()?;
        }
        if t.local.contains(&i) && !self.on_main {
            let start = matches!(event, Event::Start { .. });
            if !t.callback_ticks || (start && t.tick_may_be_long(i)) {
                self.to_main = true;
                return Ok(Turn::Wait);
            }
        }
        Ok(Turn::Go)
    }

    fn take(
        &mut self,
        core: &mut Events<'c>,
        index: u64,
        event: Event,
    ) -> Result<Taken, DistError> {
        let (i, _) = event.node_at();
        let t = &mut *self.turns;
        if t.local.contains(&i) {
            // A tick that may be long: whatever the launcher has not yet been sent goes
            // first, so that its view of the run is not held back while the tick runs (the
            // others have those reports and wait here). After the samples held back.
            let start = matches!(event, Event::Start { .. });
            let long = !t.callback_ticks || t.tick_may_be_long(i);
            if start && long && t.share.bridge.spill.is_empty() {
                t.flush()?;
                t.send_followed(true)?;
            }
            return Ok(match t.run_here(core, index, event)? {
                Some(over) => Taken::Ran { over, ticked: 0 },
                None => Taken::NotYet, // an input message is still on its way
            });
        }
        let Some(m) = ratelab_runtime::graph::lock(self.inbox).take(index) else {
            return Ok(Taken::NotYet);
        };
        let spec = &t.share.cfg.graph;
        let compute = check_tick_report(&m, index, event, spec).map_err(DistError::Peer)?;
        for &(topic, seq) in &m.published {
            // Only a topic the node publishes (a report is untrusted input).
            if spec.nodes[i].publishes.contains(&TopicId(topic)) {
                t.sent[topic] = Some(seq);
            }
        }
        core.ran_elsewhere(event, compute);
        Ok(Taken::Ran {
            over: m.stop || m.failed.is_some(),
            ticked: 0,
        })
    }

    fn taken(
        &mut self,
        _core: &mut Events<'c>,
        _index: u64,
        _event: Event,
        _ticked: u64,
    ) -> Result<Turn, DistError> {
        let t = &mut *self.turns;
        if !t.share.bridge.spill.is_empty() {
            return Ok(Turn::Wait); // samples held back: the main thread goes on
        }
        if t.kept_at.is_some_and(|at| at.elapsed() >= MAX_REPORT_WAIT) {
            t.flush()?;
        }
        Ok(Turn::Go)
    }
}

impl Turns {
    /// Node `i`'s next tick may be long: it has not ticked here yet, or its last tick took
    /// over [`CALLBACK_TICK_NS`].
    fn tick_may_be_long(&self, i: usize) -> bool {
        self.tick_ns[i].is_none_or(|ns| ns > CALLBACK_TICK_NS)
    }

    /// Run `event`, this process's, the run's `index`-th, on `core` and keep its report:
    /// `Some(over)` (the node stopped the run or failed), or `None` while an input message
    /// it must see is still on its way (a start sees exactly the messages it would see in
    /// one process). An input that does not come within [`REPLY_TIMEOUT`] fails the tick.
    fn run_here(
        &mut self,
        core: &mut RunCore,
        index: u64,
        event: Event,
    ) -> Result<Option<bool>, DistError> {
        let share = self.share.clone();
        let spec = &share.cfg.graph;
        let (i, t) = event.node_at();
        let mut failed = None;
        let mut flow = Flow::Continue;
        let mut compute = Nanos::ZERO;
        match event {
            Event::Publish { .. } => {
                // Publishing held outputs cannot fail or stop the run.
                let _ = core.run_event(event);
            }
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
                    let began = Instant::now();
                    let ticked = core.run_event(event);
                    let took = u64::try_from(began.elapsed().as_nanos()).unwrap_or(u64::MAX);
                    self.tick_ns[i] = Some(took);
                    match ticked {
                        Ok((f, c)) => (flow, compute) = (f, c),
                        Err(EndReason::NodeFailed { message, .. }) => failed = Some(message),
                        Err(other) => failed = Some(other.to_string()),
                    }
                } else {
                    core.ran_elsewhere(event, Nanos::ZERO);
                }
                share.ticks[i].fetch_add(1, Ordering::Relaxed);
            }
        }
        share.run_time.fetch_max(t.0, Ordering::Relaxed);
        let published = if failed.is_none() {
            share.bridge.forward_after(i)
        } else {
            Vec::new()
        };
        let read = read_counters(&self.held, &share.handles);
        ratelab_runtime::graph::lock(&share.batch).keep(t.0, &read);
        let over = flow == Flow::Stop || failed.is_some();
        self.kept_at.get_or_insert_with(Instant::now);
        self.outbox.push(Ticked {
            process: share.process.clone(),
            index,
            node: i,
            t_ns: t.0,
            stop: flow == Flow::Stop,
            published,
            failed: failed.map(|m| wire::cut_to_bytes(m, MAX_FAILED_BYTES)),
            publish: matches!(event, Event::Publish { .. }),
            compute_ns: compute.0,
        });
        Ok(Some(over))
    }

    /// Send the reports kept, in one message: on the last sample their ticks published when
    /// the reports ride on the samples ([`super::Spill::carrying`]), else on their own key.
    fn flush(&mut self) -> Result<(), DistError> {
        if self.outbox.is_empty() {
            // No report to carry: a sample kept (none is published outside an event of
            // this process's, which always leaves its report) still goes.
            self.share.bridge.put_kept(None)?;
            return Ok(());
        }
        let bytes = wire::encode_reports(&self.outbox);
        self.kept_at = None;
        if let Some(bytes) = self.share.bridge.put_kept(Some(bytes))? {
            self.publisher.put(bytes).wait()?;
        }
        match self.horizon.followed.as_mut() {
            Some(b) => {
                b.keep(&mut self.outbox);
                self.send_followed(false)?;
            }
            None => self.outbox.clear(),
        }
        Ok(())
    }

    /// Linked directly: send the launcher the reports kept for it to follow when they are
    /// due ([`FollowedBatch::due`]; `waiting`: the run waits here for the launcher, or is
    /// over).
    fn send_followed(&mut self, waiting: bool) -> Result<(), DistError> {
        let (Some(batch), Some(progress)) = (self.horizon.followed.as_mut(), &self.progress) else {
            return Ok(());
        };
        for bytes in batch.take_due(waiting) {
            progress.put(bytes).wait()?;
        }
        Ok(())
    }
}

/// Run this process's part of the virtual clock's run: set up `core` in `slot` (whose
/// callbacks advance it as reports and samples arrive), go on where a callback stopped
/// (`nudged`), move the horizon on as the launcher's messages on `ctl` say, and at its stop
/// wait for the last messages sent here and return the figures. Its reports go as
/// `reporting` says (and its ticks may run in Zenoh's callbacks, [`Stepper::new`]).
///
/// # Errors
/// [`DistError::Peer`] when the run cannot go on here (another process out of step, an
/// input that never came, a report that cannot be sent), on `stop`, or when the launcher
/// goes.
pub(super) fn run_lockstep(
    core: RunCore,
    share: &Arc<Share>,
    (slot, nudged): (&SharedSlot, &Receiver<()>),
    ctl: &Receiver<ToProcess>,
    reporting: Reporting,
    stop: &StopFlag,
    launcher_gone: &TokenWatch,
) -> Result<GraphState, DistError> {
    let run = Stepper::new(core, share.clone(), reporting, stop.clone());
    *ratelab_runtime::graph::lock(&slot.run) = Some(run);
    slot.wake(true);
    let failed = |e: DistError| {
        slot.take_run();
        Err(e)
    };
    let (at_ns, need) = loop {
        if let Some(e) = slot.take_error() {
            return failed(e);
        }
        if stop.is_stopped() {
            return failed(DistError::Peer("interrupted".into()));
        }
        crossbeam_channel::select! {
            recv(ctl) -> m => match m {
                Ok(ToProcess::Horizon {
                    until_ns,
                    follow_at_ns,
                }) => {
                    if let Some(r) = ratelab_runtime::graph::lock(&slot.run).as_mut() {
                        r.horizon(until_ns, follow_at_ns);
                    }
                    slot.wake(true);
                }
                Ok(ToProcess::Events { count }) => {
                    if let Some(r) = ratelab_runtime::graph::lock(&slot.run).as_mut() {
                        r.last(count);
                    }
                    slot.wake(true);
                }
                Ok(ToProcess::Stop { at_ns, need }) => break (at_ns, need),
                Ok(_) => {}
                Err(_) => return failed(DistError::Peer("the launcher's channel closed".into())),
            },
            recv(nudged) -> _ => slot.wake(true),
            default(Duration::from_millis(100)) => {
                if launcher_gone.is_gone() {
                    return failed(DistError::Peer("the launcher went away".into()));
                }
                // An input that never came fails its tick after a while: look again.
                slot.wake(true);
            }
        }
    };
    // Every event of the run taken here (the others' reports, which the launcher handed on
    // at the end): the replayed order, executors' figures and all, is the whole run's. One
    // wait for them and for the last messages below: the launcher waits a little longer for
    // the report, so this process's own error comes first.
    let deadline = Instant::now() + REPLY_TIMEOUT;
    if let Err(e) = take_the_rest(slot, nudged, (stop, launcher_gone), deadline) {
        return failed(e);
    }
    let Some(mut run) = slot.take_run() else {
        return Err(DistError::Peer("the run was not set up".into()));
    };
    run.end();
    // What went wrong here before the stop still ends this process's part in an error.
    if let Some(e) = slot.take_error() {
        return Err(e);
    }
    // The last messages sent to us are delivered before the counters are read.
    let spec = &share.cfg.graph;
    for (t, seq) in need {
        let t = TopicId(t);
        if share.inbound.contains(&t) && !share.arrivals.wait_for(t, seq, deadline, stop) {
            if stop.is_stopped() {
                return Err(DistError::Peer("interrupted".into()));
            }
            return Err(DistError::Peer(format!(
                "message {seq} on {} did not arrive within {} s of the end",
                spec.topic(t).name,
                REPLY_TIMEOUT.as_secs()
            )));
        }
    }
    Ok(run.capture(Nanos(at_ns)))
}

/// At the run's end, wait until the run in `slot` has taken every event the launcher
/// counted ([`Stepper::last`]; at once without its word), going on where a callback stopped
/// (`nudged`), until `deadline`.
///
/// # Errors
/// [`DistError::Peer`] when the run cannot go on here, on `stop`, when the launcher goes
/// (`launcher_gone`), or when the reports do not come in time.
fn take_the_rest(
    slot: &SharedSlot,
    nudged: &Receiver<()>,
    (stop, launcher_gone): (&StopFlag, &TokenWatch),
    deadline: Instant,
) -> Result<(), DistError> {
    loop {
        slot.wake(true);
        if let Some(e) = slot.take_error() {
            return Err(e);
        }
        let left = ratelab_runtime::graph::lock(&slot.run)
            .as_ref()
            .map_or(0, Stepper::left);
        if left == 0 {
            return Ok(());
        }
        if stop.is_stopped() {
            return Err(DistError::Peer("interrupted".into()));
        }
        if launcher_gone.is_gone() {
            return Err(DistError::Peer("the launcher went away".into()));
        }
        if Instant::now() >= deadline {
            return Err(DistError::Peer(format!(
                "the reports of the run's last {left} events did not arrive within {} s of its end",
                REPLY_TIMEOUT.as_secs()
            )));
        }
        crossbeam_channel::select! {
            recv(nudged) -> _ => {},
            default(Duration::from_millis(20)) => {},
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{FollowedBatch, Horizon};
    use crate::lockstep::tests::report;
    use crate::lockstep::{FOLLOWED_BATCH, FOLLOWED_MAX_AGE};
    use crate::wire::{self, MAX_TICKS_PER_MESSAGE};
    use std::time::{Duration, Instant};

    /// Between two processes linked directly, a process takes the reports a sample carries
    /// into its lockstep's inbox, as it arrives, only when every one is the publisher's,
    /// and only in a launch where the reports ride on the samples; the sample arrives
    /// either way.
    #[test]
    fn a_reader_takes_the_reports_a_sample_carries_from_its_publisher_alone() {
        use super::super::bridge::subscribe_inbound;
        use super::Slot;
        use ratelab_runtime::config::{ClockKind, RunConfig};
        use zenoh::Wait;
        let cfg = RunConfig {
            clock: ClockKind::Virtual,
            ..RunConfig::default()
        };
        let spec = cfg.graph.clone();
        let keys = crate::Keys::new(&spec.name);
        let mine = super::super::nodes_of(&spec, "policy");
        let batch = std::sync::Arc::default();
        let core = super::super::build_share(&cfg, "scripted", &mine, &batch).unwrap();
        let obs = (0..spec.topics.len())
            .map(ratelab_runtime::graph::TopicId)
            .find(|&t| spec.topic(t).name == "/obs")
            .unwrap();
        let sensor = spec.topic(obs).publisher.0;
        let session = super::super::tests::local_session();
        let publisher = session
            .declare_publisher(keys.topic("/obs"))
            .wait()
            .unwrap();
        let sample = |seq: u64| {
            let data = spec.topic(obs).msg.from_fields(&[0.1]);
            crate::wire::WireSample {
                head: crate::wire::SampleHead {
                    seq,
                    stamp_ns: seq * 20_000_000,
                    origin_ns: None,
                    sent_mono_ns: crate::wire::mono_now_ns(),
                },
                data: data.to_bytes(),
            }
            .encode()
        };
        let within = |what: &str, done: &dyn Fn() -> bool| {
            let until = Instant::now() + Duration::from_secs(10);
            while !done() {
                assert!(Instant::now() < until, "{what}");
                std::thread::sleep(Duration::from_millis(5));
            }
        };
        for carry in [true, false] {
            let (slot, _nudged) = Slot::shared(spec.clone());
            let into = (&[obs][..], Some(slot.clone()), carry);
            let inbound =
                subscribe_inbound(&session, &keys, &spec, core.handles(), into, "policy").unwrap();
            let arrived = |seq: u64| {
                let seqs = ratelab_runtime::graph::lock(&inbound.arrivals.seqs);
                super::super::bridge::arrived(&seqs, obs, seq)
            };
            let held = |index: u64| ratelab_runtime::graph::lock(&slot.inbox).take(index);
            // The publisher's report, carried.
            let theirs = wire::encode_reports(&[report("robot", 0, sensor)]);
            publisher.put(sample(0)).attachment(theirs).wait().unwrap();
            within("the first sample", &|| arrived(0));
            assert_eq!(held(0).is_some(), carry, "carry {carry}");
            // Another process's report on the publisher's sample: refused, the sample kept.
            let forged = wire::encode_reports(&[report("policy", 1, sensor)]);
            publisher.put(sample(1)).attachment(forged).wait().unwrap();
            within("the second sample", &|| arrived(1));
            assert!(held(1).is_none(), "carry {carry}");
            drop(inbound);
        }
    }

    /// Linked directly, where the launcher names no time to send from (an earlier ratelab's),
    /// it hears a process's reports in batches: a full batch, or any kept when the run waits
    /// for it here or the oldest has waited long enough; never an empty message. What it is
    /// sent is every report kept, in order, in messages the launcher accepts.
    #[test]
    fn the_launcher_follows_a_process_in_batches_and_before_it_waits() {
        let mut b = FollowedBatch::default();
        assert!(!b.due(true), "nothing kept: nothing due, even waiting");
        let mut made: Vec<_> = (0..FOLLOWED_BATCH as u64 - 1)
            .map(|i| report("robot", i, 0))
            .collect();
        b.keep(&mut made);
        assert!(made.is_empty());
        b.look(u64::MAX);
        assert!(!b.due(false), "one short of a batch");
        assert!(
            b.due(true),
            "the run waits for the launcher: due whatever the count"
        );
        b.keep(&mut vec![report("robot", FOLLOWED_BATCH as u64 - 1, 0)]);
        assert!(b.due(false), "a full batch");
        // Kept long enough: due one at a time.
        let mut one = FollowedBatch::default();
        one.keep(&mut vec![report("robot", 0, 0)]);
        assert!(!one.due(false));
        one.since = Some(Instant::now() - FOLLOWED_MAX_AGE - Duration::from_millis(1));
        assert!(one.due(false), "overdue");
        // Many kept at once (a process that waited long for the horizon): in messages the
        // launcher decodes, every report once, in order; then nothing is kept.
        let n = 3 * MAX_TICKS_PER_MESSAGE as u64 + 5;
        b.keep(
            &mut (FOLLOWED_BATCH as u64..n)
                .map(|i| report("robot", i, 0))
                .collect(),
        );
        let messages = b.take_due(false);
        assert_eq!(messages.len(), 4);
        let got: Vec<u64> = (messages.iter())
            .flat_map(|m| wire::decode_reports(m).unwrap())
            .map(|m| m.index)
            .collect();
        assert_eq!(got, (0..n).collect::<Vec<_>>());
        assert!(!b.due(true) && b.take_due(true).is_empty() && b.since.is_none());
    }

    /// Where the launcher's horizon names a run time to send from, a process sends what it
    /// has kept once its run looks at an event past it, however many or few reports it
    /// holds (not every [`FOLLOWED_BATCH`]), then nothing more for it until the next horizon
    /// names another; before it waits for the horizon, and when overdue, as before.
    #[test]
    fn a_process_sends_the_launcher_its_reports_once_its_run_passes_the_named_time() {
        let at_ns = 1_000;
        let mut b = FollowedBatch::default();
        b.follow_from(Some(at_ns));
        let mut made: Vec<_> = (0..3 * FOLLOWED_BATCH as u64)
            .map(|i| report("robot", i, 0))
            .collect();
        b.keep(&mut made);
        b.look(at_ns);
        assert!(!b.due(false), "at the time named, not past it: kept");
        assert!(b.take_due(false).is_empty());
        assert!(b.due(true), "the run waits for the horizon: due");
        b.look(at_ns - 1);
        assert!(!b.due(false), "an earlier look never takes the run back");
        b.look(at_ns + 1);
        assert!(b.due(false), "past the time named: due");
        assert_eq!(b.take_due(false).len(), 2);
        // Sent for that time: what is kept next waits for the next horizon's time.
        b.keep(&mut vec![report("robot", 3 * FOLLOWED_BATCH as u64, 0)]);
        b.look(u64::MAX / 2);
        assert!(!b.due(false), "nothing more for the same time");
        assert!(b.due(true), "but before the run waits for the horizon");
        b.follow_from(Some(u64::MAX / 2));
        assert!(!b.due(false));
        // Sent early (the run waited), the time still stands for what is kept after.
        assert_eq!(b.take_due(true).len(), 1);
        b.keep(&mut vec![report("robot", 3 * FOLLOWED_BATCH as u64 + 1, 0)]);
        assert!(!b.due(false));
        b.look(u64::MAX / 2 + 1);
        assert!(b.due(false));
        // Passed with nothing kept (everything sent before a long tick): nothing more is
        // due for that time, so the next report is not sent alone.
        assert_eq!(b.take_due(false).len(), 1);
        b.follow_from(Some(u64::MAX / 2 + 10));
        b.look(u64::MAX / 2 + 11);
        assert!(b.take_due(false).is_empty(), "nothing kept: nothing sent");
        b.keep(&mut vec![report("robot", 3 * FOLLOWED_BATCH as u64 + 2, 0)]);
        assert!(!b.due(false), "the time was passed already");
    }

    /// The horizon admits an event at or before it and makes the run wait past it (and
    /// before the launcher's first word); an older horizon, overtaken, is ignored.
    #[test]
    fn the_horizon_admits_what_it_reaches_and_ignores_an_older_one() {
        for direct in [false, true] {
            let mut h = Horizon::new(direct);
            assert!(!h.admits(0) && h.waits, "no horizon yet: the run waits");
            h.waits = false;
            h.moved(1_000, Some(500));
            assert!(
                h.admits(0) && h.admits(1_000) && !h.waits,
                "direct {direct}"
            );
            assert!(
                !h.admits(1_001) && h.waits,
                "past the horizon: the run waits"
            );
            h.moved(900, Some(450));
            assert_eq!(h.until_ns, Some(1_000), "an older horizon changes nothing");
            if let Some(b) = h.followed.as_ref() {
                assert_eq!(b.follow_at_ns, Some(500), "nor the time it names");
            }
            h.moved(2_000, Some(1_500));
            assert!(h.admits(1_001));
        }
        assert!(
            Horizon::new(false).followed.is_none(),
            "a star keeps nothing"
        );
    }

    /// Linked directly, what the run looks at is what sends the launcher the reports kept
    /// for it: once the run looks at an event past the time the horizon names, they are
    /// due while the run is still well inside the horizon (the launcher moves the horizon on
    /// before the run reaches it: issue 76's lockstep, the launcher woken once a horizon).
    #[test]
    fn looking_past_the_named_time_sends_the_launcher_its_reports_inside_the_horizon() {
        let mut h = Horizon::new(true);
        h.moved(1_000, Some(500));
        h.followed
            .as_mut()
            .unwrap()
            .keep(&mut vec![report("robot", 0, 0)]);
        let due = |h: &Horizon| h.followed.as_ref().unwrap().due(h.waits);
        assert!(h.admits(500) && !due(&h), "at the time named: kept");
        assert!(h.admits(501) && due(&h), "past it, inside the horizon: due");
        assert!(!h.waits);
        assert_eq!(h.followed.as_mut().unwrap().take_due(h.waits).len(), 1);
        // The next horizon names the next time; nothing is due until the run passes it.
        h.moved(2_000, Some(1_500));
        h.followed
            .as_mut()
            .unwrap()
            .keep(&mut vec![report("robot", 1, 0)]);
        assert!(h.admits(1_200) && !due(&h));
        assert!(h.admits(1_501) && due(&h));
    }
}
