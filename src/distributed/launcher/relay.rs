//! The lockstep's reports, gathered and handed on by the launcher (virtual clock).
//!
//! Each process sends the reports of its events once, to the launcher ([`Keys::ticked`]),
//! whose session is the router of the launch's star. The launcher follows the run's one
//! order of events as the reports come in ([`Follower`], on the thread that receives them:
//! Zenoh's, through the one drive loop, `drive`, taking events) and, when an event is
//! next, sends its node's process every report that process has not had, in one message on
//! the process's own key ([`Keys::relayed`]): before its turn a process must know every
//! event before it ([`crate::lockstep`]). A process that has [`MAX_RELAYED`] reports waiting
//! for it without a turn is sent them then, and at the run's end every process is sent the
//! rest ([`Relay::hand_over_all`]), so each replays the whole run.
//!
//! So an instant in which P processes each run an event costs P messages in and P out,
//! where each process sending its reports to every other cost P (P − 1). A launch linked
//! directly ([`crate::launcher::LaunchOptions::star`]) is small, and there every process
//! hears every other's reports itself, over their own link: the launcher follows them as
//! here, from the batches each process sends it ([`crate::Keys::progress`],
//! [`crate::lockstep::follow_at`]), but hands nothing on during the run
//! ([`Course::relays`]); at its end it hands each process the last [`MAX_RELAYED`] it took,
//! for the rare report that reached it and not another process (a process that went
//! between its two puts; a process ignores those it has). A report that reached the
//! others and not the launcher is not counted in the run's events, so nobody waits for it. The messages go
//! out through the launcher's outbox ([`super::outbox`]: from its own thread, as Zenoh's
//! one thread must not wait to send, or when small and nothing is queued, at once), after
//! any sample handed in before them; a process's report also tells its outbox that it
//! reads ([`Outbox::answered`]). The callback tells the launcher's main thread when the
//! horizon must move on.

use super::outbox::{Out, Outbox, Outboxes};
use crate::lockstep::{
    check_tick_report, horizon_low, horizon_periods, subscribe_progress, subscribe_reports,
    TickInbox,
};
use crate::wire::{self, Ticked, MAX_RELAYED};
use crate::{DistError, Keys};
use crossbeam_channel::{Receiver, Sender};
use ratelab_core::time::Nanos;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::lock;
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::graph::{NodeId, TopicId};
use ratelab_runtime::runcore::drive::{drive, Cursor, DrivePolicy, Drove, Taken};
use ratelab_runtime::runcore::Follower;
use ratelab_runtime::scheduler::{EndReason, Event, RunEnd};
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use zenoh::Wait;

/// A run's end at `at`: node `node` (of `spec`) failed with `message`.
pub(super) fn failed(spec: &GraphSpec, node: usize, at: Nanos, message: String) -> RunEnd {
    let name = spec.nodes.get(node).map_or("?", |n| n.name.as_str());
    RunEnd {
        at,
        reason: EndReason::NodeFailed {
            node: name.to_string(),
            message,
        },
    }
}

/// The launcher's relay of the lockstep's reports, shared by Zenoh's callbacks and the
/// launcher's main thread.
pub(super) struct Relay {
    spec: GraphSpec,
    /// Per process (placement order), the publisher of its relayed key and the outbox its
    /// messages go out through (the one its crossing topics' samples take, so that a
    /// sample a report names reaches it first).
    outs: Vec<(Out, Arc<Outbox>)>,
    /// Per node of the graph, its process's place in `outs`.
    process_of: Vec<usize>,
    /// The run as followed so far (`None` before it starts: what comes then is not a
    /// report).
    course: Mutex<Option<Course>>,
    /// Tells the main thread to look: the horizon low, the run over.
    nudge: Sender<()>,
    /// The processes are linked directly: they hear each other's reports
    /// ([`Course::relays`]).
    direct: bool,
}

/// A relay in place: the relay, the main thread's end of its nudges and the subscriptions
/// to the processes' reports (kept for the run).
pub(super) struct Relaying {
    /// The relay.
    pub(super) relay: Arc<Relay>,
    /// Where the relay tells the main thread to look.
    pub(super) nudged: Receiver<()>,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

/// Where the run is, as the relay has followed it.
pub(super) struct Progress {
    /// Events taken (the next one's index).
    pub(super) index: u64,
    /// The next event's node and run time (`None` once the run is over).
    pub(super) next: Option<(usize, Nanos)>,
    /// How the run ended, once it has.
    pub(super) end: Option<RunEnd>,
}

/// What the run came to, as the relay counted it.
pub(super) struct Tally {
    /// Events taken: the run's events.
    pub(super) events: u64,
    /// Ticks started among them.
    pub(super) started: u64,
    /// Distinct instants they fell on.
    pub(super) instants: u64,
    /// Per topic, the newest seq its publisher's process reported sent across.
    pub(super) published: Vec<Option<u64>>,
}

/// The run as the relay follows it (under [`Relay::course`]'s lock).
struct Course {
    order: Follower,
    /// Events taken (its index: the next one's) and the next event, once drawn and until
    /// its report is taken.
    cursor: Cursor<Event>,
    duration: Nanos,
    /// How far the horizon reaches ahead, ns (its move is due at half of it).
    lookahead: u64,
    inbox: TickInbox,
    /// The reports taken, the first numbered `log_from` (those every process has had are
    /// dropped).
    log: VecDeque<Ticked>,
    log_from: u64,
    /// Per process, the reports below this index it has been sent (or were its own).
    given: Vec<u64>,
    /// The horizon the main thread last sent, ns.
    horizon: Option<u64>,
    /// Whether the processes are handed the reports here (a star), or hear them from each
    /// other (a launch linked directly): then every report but the last [`MAX_RELAYED`]
    /// counts as had once taken, and those are handed on at the end.
    relays: bool,
    counts: Counts,
    /// Reports accepted so far, in turn or ahead of it.
    accepted: u64,
    end: Option<RunEnd>,
}

/// What the reports taken came to, beside their count.
#[derive(Default)]
struct Counts {
    published: Vec<Option<u64>>,
    started: u64,
    instants: u64,
    last_t: Option<Nanos>,
}

/// The relay's event source for the drive loop ([`drive`], taking events): every
/// event is taken from its process's report, once it is in; a report out of step, a stop
/// or a failure ends the run.
struct Follow<'a> {
    spec: &'a GraphSpec,
    inbox: &'a mut TickInbox,
    log: &'a mut VecDeque<Ticked>,
    counts: &'a mut Counts,
    end: &'a mut Option<RunEnd>,
}

impl DrivePolicy<Event, Follower> for Follow<'_> {
    /// A report out of step: the run's end (its node's failure).
    type Error = RunEnd;

    fn take(&mut self, order: &mut Follower, index: u64, event: Event) -> Result<Taken, RunEnd> {
        let spec = self.spec;
        let (i, t) = event.node_at();
        let Some(m) = self.inbox.take(index) else {
            return Ok(Taken::NotYet);
        };
        let compute = check_tick_report(&m, index, event, spec)
            .map_err(|message| failed(spec, i, t, message))?;
        let c = &mut *self.counts;
        if let Event::Start { .. } = event {
            c.started += 1;
        }
        order.ran_elsewhere(event, compute);
        if c.last_t != Some(t) {
            c.instants += 1;
            c.last_t = Some(t);
        }
        for &(topic, seq) in &m.published {
            // Only a topic the node publishes (a report is untrusted input).
            if spec.nodes[i].publishes.contains(&TopicId(topic)) {
                c.published[topic] = Some(seq);
            }
        }
        if let Some(message) = &m.failed {
            *self.end = Some(failed(spec, i, t, message.clone()));
        } else if m.stop {
            *self.end = Some(RunEnd {
                at: t,
                reason: EndReason::NodeStopped,
            });
        }
        let over = self.end.is_some();
        self.log.push_back(m);
        Ok(Taken::Ran { over, ticked: 0 })
    }
}

impl Course {
    /// Take in a process's message of reports `ms` (each kept until its turn, counted in
    /// [`Course::accepted`]); too many ahead of their turn fail the next event.
    fn take_in(&mut self, ms: Vec<Ticked>, spec: &GraphSpec) {
        for m in ms {
            if let Err(e) = self.inbox.accept(m, spec) {
                self.fail_next(spec, e.to_string());
                break;
            }
            self.accepted += 1;
        }
    }

    /// `at`, or the latest run time of a report kept ahead of its turn when later: where a
    /// run the launcher ends early ends, linked directly (the processes may have run on
    /// reports the launcher never had, or lacks yet).
    fn reached(&self, at: Nanos) -> Nanos {
        self.inbox.newest_ns().map_or(at, |n| Nanos(n).max(at))
    }

    /// Take every report whose turn has come, in the run's order, drawing each next event
    /// (the drive loop, [`Follow`] its event source); the end where one says so (a stop, a
    /// failure, a process out of step) or where the run's duration is reached.
    fn advance(&mut self, spec: &GraphSpec) {
        if self.end.is_some() {
            return;
        }
        let mut follow = Follow {
            spec,
            inbox: &mut self.inbox,
            log: &mut self.log,
            counts: &mut self.counts,
            end: &mut self.end,
        };
        match drive(&mut self.order, &mut self.cursor, &mut follow, None, None) {
            Ok(Drove::Exhausted) => {
                self.end = Some(RunEnd {
                    at: self.duration,
                    reason: EndReason::Duration,
                });
            }
            // The reports say the end: a follower knows none, runs none and takes no intake.
            Ok(Drove::Over | Drove::Waiting | Drove::Limit | Drove::Stopped) => {}
            Ok(Drove::Ended(_) | Drove::Left) => {}
            Err(end) => self.end = Some(end),
        }
    }

    /// The run cannot go on: `message`, at the next event (its node's failure).
    fn fail_next(&mut self, spec: &GraphSpec, message: String) {
        let (i, t) = self
            .cursor
            .next()
            .map_or((spec.actuator.0, self.order.now()), |e| e.node_at());
        if self.end.is_none() {
            self.end = Some(failed(spec, i, t, message));
        }
    }

    /// The messages of reports due now, each (process's place, bytes): to the next event's
    /// process, every report it has not had (it waits for them); to any other, its reports
    /// once [`MAX_RELAYED`] wait for it. Then the reports every process has had are
    /// dropped.
    fn due(&mut self, process_of: &[usize]) -> Vec<(usize, Vec<u8>)> {
        let mut out = Vec::new();
        if !self.relays {
            let tail = self.cursor.index().saturating_sub(MAX_RELAYED as u64);
            self.given
                .iter_mut()
                .for_each(|had| *had = (*had).max(tail));
            self.forget_handed();
            return out;
        }
        if self.end.is_none() {
            if let Some(e) = self.cursor.next() {
                if let Some(&p) = process_of.get(e.node_at().0) {
                    self.hand(p, process_of, &mut out);
                }
            }
        }
        let waited: Vec<usize> = (self.given.iter().enumerate())
            .filter(|(_, had)| self.cursor.index().saturating_sub(**had) >= MAX_RELAYED as u64)
            .map(|(p, _)| p)
            .collect();
        for p in waited {
            self.hand(p, process_of, &mut out);
        }
        self.forget_handed();
        out
    }

    /// Hand process `p` every report it has not had (not its own), in messages of at most
    /// [`MAX_RELAYED`], onto `out`.
    fn hand(&mut self, p: usize, process_of: &[usize], out: &mut Vec<(usize, Vec<u8>)>) {
        let Some(given) = self.given.get_mut(p) else {
            return;
        };
        let index = self.cursor.index();
        let from = (*given).max(self.log_from);
        *given = index;
        if from >= index {
            return;
        }
        let skip = usize::try_from(from - self.log_from).unwrap_or(usize::MAX);
        let theirs: Vec<&Ticked> = (self.log.iter().skip(skip))
            .filter(|m| process_of.get(m.node) != Some(&p))
            .collect();
        for chunk in theirs.chunks(MAX_RELAYED) {
            out.push((p, wire::encode_relayed(chunk)));
        }
    }

    /// Drop the reports every process has been handed.
    fn forget_handed(&mut self) {
        let all_had = self
            .given
            .iter()
            .copied()
            .min()
            .unwrap_or(self.cursor.index());
        while self.log_from < all_had {
            if self.log.pop_front().is_none() {
                self.log_from = all_had;
                break;
            }
            self.log_from += 1;
        }
    }
}

impl Relay {
    /// A relay for the processes `names` (placement order) of `spec`'s graph, on the
    /// launcher's `session` (the router): a publisher per process's relayed key, whose
    /// messages go out through `outbox`, and a subscription to every process's reports,
    /// which it follows once the run begins ([`Relay::begin`]). `direct`: the processes
    /// are linked directly and hear each other's reports; nothing is handed on.
    ///
    /// # Errors
    /// [`DistError::Zenoh`] when a publisher or subscriber cannot be declared.
    pub(super) fn start(
        session: &zenoh::Session,
        keys: &Keys,
        spec: &GraphSpec,
        (names, outboxes): (&[String], &Outboxes),
        direct: bool,
    ) -> Result<Relaying, DistError> {
        let block = zenoh::qos::CongestionControl::Block;
        let mut outs = Vec::with_capacity(names.len());
        for p in names {
            let publisher = session
                .declare_publisher(keys.relayed(p))
                .congestion_control(block)
                .wait()?;
            let outbox = outboxes
                .of(p)
                .ok_or_else(|| DistError::Usage(format!("no outbox for process '{p}'")))?;
            outs.push((Arc::new(publisher), outbox.clone()));
        }
        let process_of = (0..spec.nodes.len())
            .map(|i| {
                let p = spec.process_of(NodeId(i));
                names.iter().position(|n| *n == p).unwrap_or(usize::MAX)
            })
            .collect();
        let (nudge, nudged) = crossbeam_channel::bounded(1);
        let relay = Arc::new(Relay {
            spec: spec.clone(),
            outs,
            process_of,
            course: Mutex::new(None),
            nudge,
            direct,
        });
        let taker = relay.clone();
        // Linked directly, each process sends the launcher its reports in batches to follow
        // (`lockstep::follow_at`), where the others hear each as it is made.
        let take = move |ms| taker.take(ms);
        let subscribers = if direct {
            subscribe_progress(session, keys, names, take)?
        } else {
            subscribe_reports(session, keys, names, None, take)?
        };
        Ok(Relaying {
            relay,
            nudged,
            _subscribers: subscribers,
        })
    }

    /// Begin following the run of `cfg` (every process ready, none run yet: anything that
    /// came before is not a report): its first event drawn. Returns how far the horizon
    /// reaches ahead, ns ([`horizon_periods`] periods of the fastest node; `paced`: a lab
    /// follows the run at a pace).
    ///
    /// # Errors
    /// [`DistError::Usage`] for a node rate a graph file should not have let through.
    pub(super) fn begin(&self, cfg: &RunConfig, paced: bool) -> Result<u64, DistError> {
        let order = Follower::new(cfg).map_err(|e| DistError::Usage(e.to_string()))?;
        let periods = horizon_periods(&order, paced);
        let lookahead = order.shortest_period().0.saturating_mul(periods);
        let mut course = Course {
            order,
            duration: cfg.duration,
            lookahead,
            cursor: Cursor::default(),
            inbox: TickInbox::new(),
            log: VecDeque::new(),
            log_from: 0,
            given: vec![0; self.outs.len()],
            horizon: None,
            relays: !self.direct,
            counts: Counts {
                published: vec![None; self.spec.topics.len()],
                ..Counts::default()
            },
            accepted: 0,
            end: None,
        };
        course.advance(&self.spec);
        *lock(&self.course) = Some(course);
        Ok(lookahead)
    }

    /// Take in a process's message of reports (on Zenoh's receive thread), follow the run
    /// as far as they let it go, and hand the next event's process what it waits for.
    fn take(&self, ms: Vec<Ticked>) {
        // Its process reported (the message's key names it, and only it may put there,
        // `crate::access`; every report in it is that process's, `decode_report`): it
        // reads what it is handed.
        if let Some(m) = ms.first() {
            if let Some((_, outbox)) = self.outs.iter().find(|(_, o)| o.process() == m.process) {
                outbox.answered();
            }
        }
        let (due, wake) = {
            let mut guard = lock(&self.course);
            let Some(c) = guard.as_mut() else { return };
            if c.end.is_some() {
                return;
            }
            c.take_in(ms, &self.spec);
            c.advance(&self.spec);
            let low = match (c.horizon, c.cursor.next()) {
                (Some(h), Some(e)) => horizon_low(h, e.node_at().1 .0, c.lookahead),
                _ => false,
            };
            (c.due(&self.process_of), low || c.end.is_some())
        };
        self.send(due);
        if wake {
            let _ = self.nudge.try_send(());
        }
    }

    /// Hand `messages` ((process's place, bytes) each) to the outbox, in order.
    fn send(&self, messages: Vec<(usize, Vec<u8>)>) {
        for (p, bytes) in messages {
            if let Some((out, outbox)) = self.outs.get(p) {
                outbox.put(out, bytes.into(), false);
            }
        }
    }

    /// The processes send the launcher their reports in batches (linked directly): its
    /// view of the run may be behind theirs.
    pub(super) fn follows_in_batches(&self) -> bool {
        self.direct
    }

    /// How many reports the launcher has taken in so far (in turn or ahead of it): it
    /// stands still once no process sends more.
    pub(super) fn accepted(&self) -> u64 {
        lock(&self.course).as_ref().map_or(0, |c| c.accepted)
    }

    /// `at`, or later when the processes reported events past it (linked directly, they may
    /// run on reports the launcher never had, or lacks yet): where a run the launcher ends
    /// early ends.
    pub(super) fn at_least_reported(&self, at: Nanos) -> Nanos {
        lock(&self.course).as_ref().map_or(at, |c| c.reached(at))
    }

    /// Where the run is.
    pub(super) fn progress(&self) -> Progress {
        match lock(&self.course).as_ref() {
            Some(c) => Progress {
                index: c.cursor.index(),
                next: c.cursor.next().map(|e| e.node_at()),
                end: c.end.clone(),
            },
            None => Progress {
                index: 0,
                next: None,
                end: None,
            },
        }
    }

    /// The main thread let the processes run up to `until_ns`.
    pub(super) fn set_horizon(&self, until_ns: u64) {
        if let Some(c) = lock(&self.course).as_mut() {
            c.horizon = Some(until_ns);
        }
    }

    /// End the run with `end`, unless it has ended already: the end that stands (reports
    /// that come after it are not followed).
    pub(super) fn finish(&self, end: RunEnd) -> RunEnd {
        match lock(&self.course).as_mut() {
            Some(c) => c.end.get_or_insert(end).clone(),
            None => end,
        }
    }

    /// End the run as interrupted (Ctrl-C), at the newest instant drawn, unless it has
    /// ended already: the end that stands.
    pub(super) fn interrupt(&self) -> RunEnd {
        match lock(&self.course).as_mut() {
            Some(c) => {
                // Linked directly, a process may have run past the launcher's view.
                let at = c.reached(c.order.now());
                c.end
                    .get_or_insert(RunEnd {
                        at,
                        reason: EndReason::Interrupted,
                    })
                    .clone()
            }
            None => RunEnd {
                at: Nanos::ZERO,
                reason: EndReason::Interrupted,
            },
        }
    }

    /// At the run's end: send every process every report it has not had, so that each
    /// replays the whole run before it reports.
    pub(super) fn hand_over_all(&self) {
        let mut due = Vec::new();
        if let Some(c) = lock(&self.course).as_mut() {
            for p in 0..c.given.len() {
                c.hand(p, &self.process_of, &mut due);
            }
            c.forget_handed();
        }
        self.send(due);
    }

    /// What the run came to.
    pub(super) fn tally(&self) -> Tally {
        match lock(&self.course).as_ref() {
            Some(c) => Tally {
                events: c.cursor.index(),
                started: c.counts.started,
                instants: c.counts.instants,
                published: c.counts.published.clone(),
            },
            None => Tally {
                events: 0,
                started: 0,
                instants: 0,
                published: vec![None; self.spec.topics.len()],
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lockstep::tests::report;

    /// A course of a graph of three processes, nodes 0, 1, 2 in processes 0, 1, 2, with
    /// `n` reports taken (node `k % 3`'s at index `k`), none handed on yet.
    fn course_with(n: u64) -> Course {
        let (mut c, _, _) = following(100);
        c.cursor = Cursor::at(n);
        c.log = (0..n)
            .map(|k| report(&format!("p{}", k % 3), k, (k % 3) as usize))
            .collect();
        c.given = vec![0; 3];
        c
    }

    fn decoded(bytes: &[u8]) -> Vec<u64> {
        wire::decode_relayed(bytes)
            .unwrap()
            .iter()
            .map(|m| m.index)
            .collect()
    }

    #[test]
    fn a_process_is_handed_the_others_reports_once_and_never_its_own() {
        let process_of = [0, 1, 2];
        let mut c = course_with(5);
        let mut out = Vec::new();
        c.hand(1, &process_of, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].0, 1);
        assert_eq!(decoded(&out[0].1), [0, 2, 3], "not 1 and 4, its own");
        // Nothing new: nothing handed.
        out.clear();
        c.hand(1, &process_of, &mut out);
        assert!(out.is_empty());
        // What every process has had is forgotten; the rest is kept for the others.
        c.forget_handed();
        assert_eq!((c.log_from, c.log.len()), (0, 5));
        c.hand(0, &process_of, &mut out);
        c.hand(2, &process_of, &mut out);
        c.forget_handed();
        assert_eq!((c.log_from, c.log.len()), (5, 0));
        assert_eq!(decoded(&out[0].1), [1, 2, 4]);
        assert_eq!(decoded(&out[1].1), [0, 1, 3, 4]);
    }

    #[test]
    fn a_process_without_a_turn_is_handed_its_reports_in_messages_of_a_bounded_size() {
        let process_of = [0, 1, 2];
        let n = 3 * MAX_RELAYED as u64;
        let mut c = course_with(n);
        // Every process has waited past the bound: each is handed its reports (two
        // thirds of them the others'), in messages of at most MAX_RELAYED.
        let out = c.due(&process_of);
        assert_eq!(out.len(), 6, "two messages for each of three processes");
        for (p, bytes) in &out {
            let got = wire::decode_relayed(bytes).unwrap();
            assert!(got.len() <= MAX_RELAYED);
            assert!(got.iter().all(|m| m.node != *p));
        }
        assert_eq!(c.log.len(), 0, "all handed, all forgotten");
        assert_eq!(c.given, vec![n; 3]);
    }

    #[test]
    fn linked_directly_only_the_last_reports_are_kept_and_handed_on_at_the_end() {
        // The processes hear each other's reports: none is handed on during the run,
        // whether a process's turn comes or it has waited past the bound, and only the
        // last MAX_RELAYED are kept (a long run holds no more); at the end those go to
        // every process, in case one went before its last reports reached the others.
        let process_of = [0, 1, 2];
        let n = 3 * MAX_RELAYED as u64;
        let mut c = course_with(n);
        c.relays = false;
        assert!(c.due(&process_of).is_empty());
        let tail = n - MAX_RELAYED as u64;
        assert_eq!((c.log_from, c.log.len()), (tail, MAX_RELAYED));
        assert_eq!(c.given, vec![tail; 3]);
        let mut out = Vec::new();
        for p in 0..3 {
            c.hand(p, &process_of, &mut out);
        }
        for (p, bytes) in &out {
            let got = decoded(bytes);
            assert!(
                got.iter().all(|&i| i >= tail && i % 3 != *p as u64),
                "{p}: {got:?}"
            );
        }
        let handed: usize = out.iter().map(|(_, b)| decoded(b).len()).sum();
        assert_eq!(
            handed,
            2 * MAX_RELAYED,
            "each of the tail to the two others"
        );
    }

    /// A course of the chapter's graph for `duration_ms`, nothing taken yet, and the run's
    /// events in order (drawn by a follower of its own).
    fn following(duration_ms: u64) -> (Course, Vec<Event>, RunConfig) {
        let cfg = RunConfig {
            duration: Nanos(duration_ms * 1_000_000),
            ..RunConfig::default()
        };
        let mut order = Follower::new(&cfg).unwrap();
        let mut events = Vec::new();
        while let Some(e) = order.next_event() {
            order.ran_elsewhere(e, Nanos::ZERO);
            events.push(e);
        }
        let course = Course {
            order: Follower::new(&cfg).unwrap(),
            cursor: Cursor::default(),
            duration: cfg.duration,
            lookahead: 1,
            inbox: TickInbox::new(),
            log: VecDeque::new(),
            log_from: 0,
            given: vec![0; 2],
            horizon: None,
            relays: true,
            counts: Counts {
                published: vec![None; cfg.graph.topics.len()],
                ..Counts::default()
            },
            accepted: 0,
            end: None,
        };
        (course, events, cfg)
    }

    /// The report of `event`, the run's `index`-th, as its node's process sends it.
    fn report_of(spec: &GraphSpec, index: u64, event: Event) -> Ticked {
        let (i, t) = event.node_at();
        Ticked {
            process: spec.process_of(NodeId(i)),
            t_ns: t.0,
            publish: matches!(event, Event::Publish { .. }),
            ..report("", index, i)
        }
    }

    /// Linked directly, a process gone with reports only the others had leaves the
    /// launcher's view at its first missing event, while the others' reports past it come
    /// in ahead of their turn: the launcher counts them coming (it ends the run once they
    /// stop) and ends it where the furthest got, not where its view stopped.
    #[test]
    fn a_run_ended_early_ends_where_the_furthest_report_says() {
        let (mut c, events, cfg) = following(100);
        let spec = &cfg.graph;
        // The policy's first event's report never comes; everything of the robot's does.
        let lost = (events.iter())
            .position(|e| spec.process_of(NodeId(e.node_at().0)) == "policy")
            .unwrap();
        let robots: Vec<Ticked> = (events.iter().enumerate())
            .filter(|(_, e)| spec.process_of(NodeId(e.node_at().0)) == "robot")
            .map(|(k, e)| report_of(spec, k as u64, *e))
            .collect();
        let newest = robots.iter().map(|m| m.t_ns).max().unwrap();
        let before = robots.iter().filter(|m| m.index < lost as u64).count();
        c.take_in(robots.clone(), spec);
        c.advance(spec);
        assert_eq!(
            c.cursor.index(),
            lost as u64,
            "the view stops at the lost report"
        );
        assert_eq!(
            c.accepted,
            robots.len() as u64,
            "every report counted coming"
        );
        let view = events[lost].node_at().1;
        assert!(Nanos(newest) > view);
        assert_eq!(c.reached(view), Nanos(newest));
        // In step (nothing kept ahead), the view is where the run is.
        let (mut d, _, _) = following(100);
        d.take_in(robots[..before].to_vec(), spec);
        d.advance(spec);
        assert_eq!(d.reached(view), view);
    }

    #[test]
    fn the_relay_follows_every_report_to_the_run_s_duration() {
        let (mut c, events, cfg) = following(100);
        let spec = &cfg.graph;
        // The first half in: followed that far, and waiting.
        let half = events.len() / 2;
        for (k, e) in events.iter().enumerate().take(half) {
            c.inbox.accept(report_of(spec, k as u64, *e), spec).unwrap();
        }
        c.advance(spec);
        assert_eq!((c.cursor.index(), c.end.clone()), (half as u64, None));
        assert_eq!(
            c.cursor.next(),
            Some(events[half]),
            "the next event drawn, kept"
        );
        for (k, e) in events.iter().enumerate().skip(half) {
            c.inbox.accept(report_of(spec, k as u64, *e), spec).unwrap();
        }
        c.advance(spec);
        assert_eq!(c.cursor.index(), events.len() as u64);
        assert_eq!(
            c.end,
            Some(RunEnd {
                at: cfg.duration,
                reason: EndReason::Duration
            })
        );
        let starts = events.iter().filter(|e| matches!(e, Event::Start { .. }));
        assert_eq!(c.counts.started, starts.count() as u64);
        assert_eq!(c.counts.instants, 6, "0, 20, …, 100 ms");
        assert_eq!(
            c.log.len(),
            events.len(),
            "every report kept for the processes"
        );
    }

    #[test]
    fn a_report_out_of_step_ends_the_run_before_its_event_and_a_stop_after_it() {
        let (mut c, events, cfg) = following(100);
        let spec = &cfg.graph;
        c.inbox.accept(report_of(spec, 0, events[0]), spec).unwrap();
        let mut wrong = report_of(spec, 1, events[1]);
        wrong.t_ns += 1;
        c.inbox.accept(wrong, spec).unwrap();
        c.advance(spec);
        let (node, at) = events[1].node_at();
        assert!(
            matches!(
                &c.end,
                Some(RunEnd { at: t, reason: EndReason::NodeFailed { node: n, message } })
                    if *t == at && *n == spec.nodes[node].name && message.contains("out of step")
            ),
            "{:?}",
            c.end
        );
        assert_eq!(c.cursor.index(), 1, "the event out of step is not taken");
        assert_eq!(c.cursor.next(), Some(events[1]));

        let (mut c, events, cfg) = following(100);
        let spec = &cfg.graph;
        let stop_at = events
            .iter()
            .position(|e| matches!(e, Event::Start { .. }) && e.node_at().1 > Nanos::ZERO)
            .unwrap();
        for (k, e) in events.iter().enumerate().take(stop_at + 2) {
            let mut m = report_of(spec, k as u64, *e);
            m.stop = k == stop_at;
            c.inbox.accept(m, spec).unwrap();
        }
        c.advance(spec);
        assert_eq!(
            c.end,
            Some(RunEnd {
                at: events[stop_at].node_at().1,
                reason: EndReason::NodeStopped
            })
        );
        assert_eq!(
            c.cursor.index(),
            stop_at as u64 + 1,
            "the stop is taken, nothing after"
        );
    }
}
