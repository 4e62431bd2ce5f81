//! Topics as each subscription receives them: a [`Subscription`] is one subscription's
//! queue of a topic — named, thread-safe, bounded, read latest-wins or in order — with its
//! QoS and counters (a topic of several subscribers has one per subscriber:
//! `ratelab::msg::AnyTopic`). The chapter's `Topic` (ch2.8) is this with its one subscriber.
//!
//! The drop rule is the chapter's (ch2.8, `Topic`): a subscription buffers at most `depth`
//! messages (its history depth, in QoS terms). Publishing into a full buffer evicts the
//! oldest message; that eviction is a **drop** exactly when the evicted message was never
//! read, i.e. its `seq` is above the read high-water mark. Reading with
//! [`Subscription::read`] returns the newest message and moves the high-water mark past
//! everything buffered: a latest-wins subscriber that caught up skips the backlog.
//! The drop counter is how a rate mismatch becomes visible.
//!
//! A topic also carries its [`TopicQos`] ([`crate::qos`]): keep-all history with a cap
//! (a publish into a cap full of unread messages is *refused*), FIFO delivery (a read takes
//! the oldest unread message), a lifespan (a message older than it is discarded, *expired*,
//! before a read can return it), a deadline (misses counted per period on the publisher's
//! side, *offered*, and on the subscriber's, *requested*) and a seeded lossy link (messages
//! in flight for `delay ± jitter`; a best-effort link *loses* some, a reliable one
//! *retransmits* them). Time enters through the `now` every operation takes, so under the
//! virtual clock all of it is deterministic. Every message published is accounted for:
//! `published = seen + dropped + expired + lost + refused + unmatched + before join + unseen
//! buffered + in flight` (*unmatched*: published while the subscription was left unconnected,
//! its requested QoS incompatible with the offered, [`crate::qos::compat`]; *before join*:
//! published before a late-joining subscription came into being and not kept for it).
//!
//! A topic may carry [`Tap`]s, each told of every message as it is published (before the
//! drop rule or a link decides its fate): how a run offers its topics outside without
//! changing them (`ratelab::ros2`), and how a graph across processes forwards each message
//! to the process that subscribes (`ratelab::distributed`).

use crate::qos::{Delivery, History, Link, QosCounter, Reliability, TopicQos, MAX_ATTEMPTS};
use crate::time::Nanos;
use rand_distr::{Bernoulli, Distribution, Uniform};
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

/// One published value.
#[derive(Clone, Debug, PartialEq)]
pub struct Message<T> {
    /// The payload.
    pub data: T,
    /// Run time at which the message was published.
    pub stamp: Nanos,
    /// Per-topic sequence number, from 0, in publish order.
    pub seq: u64,
    /// The stamp of the sensor reading this value was derived from, when there is one;
    /// a downstream node measures sense→act latency as `now - origin_stamp`.
    pub origin_stamp: Option<Nanos>,
}

/// Told of every message published on a topic, as it is published, on the publisher's
/// thread and under the topic's lock: it must be quick (a channel send) and must not touch
/// the topic. Added with [`Subscription::add_tap`].
pub type Tap<T> = Box<dyn Fn(&Message<T>) + Send + Sync>;

/// A topic's counters at one instant.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TopicStats {
    /// Messages published so far.
    pub published: u64,
    /// Messages evicted from a full buffer before any read caught up with them.
    pub dropped: u64,
    /// Messages a subscriber has read or read past (a latest-wins read marks everything
    /// buffered as seen).
    pub seen: u64,
    /// Reads that returned a message the subscriber had already read: nothing new arrived
    /// since its last read (a publisher slower than its subscriber). The mirror image of a
    /// drop: there a message is never read, here one is read again.
    pub stale_reads: u64,
    /// Stamp of the newest message published (zero before the first). With
    /// [`TopicStats::published`] at two instants it gives the exact rate of the messages
    /// published between them: `Δpublished / Δlast_stamp`.
    pub last_stamp: Nanos,
    /// The current history depth (keep-last depth or keep-all cap), ≥ 1.
    pub depth: usize,
    /// Unread messages discarded because they outlived the lifespan.
    pub expired: u64,
    /// Publishes refused by a keep-all queue full of unread messages.
    pub refused: u64,
    /// Messages the link lost (best effort), or gave up on after [`MAX_ATTEMPTS`] sends.
    pub lost: u64,
    /// Extra sends of a reliable link.
    pub retransmitted: u64,
    /// Messages on the link, not yet arrived.
    pub in_flight: u64,
    /// Deadline periods the publisher let pass without publishing (ROS 2's *offered
    /// deadline missed*): a gap of `g` between messages misses `⌈g / deadline⌉ − 1`.
    pub offered_deadline_missed: u64,
    /// Deadline periods that passed with no message arriving at the subscriber (ROS 2's
    /// *requested deadline missed*); beyond the offered ones, a link's losses and delays.
    pub requested_deadline_missed: u64,
    /// Messages published while the subscription was not matched to its publisher (its
    /// requested QoS incompatible with the offered, [`crate::qos::compat`]): they never
    /// reached it, as ROS 2 never connects such a pair.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub unmatched: u64,
    /// Messages published before a late-joining subscription came into being
    /// ([`Subscription::set_joins_at`]) that it never received: all of them from a volatile
    /// topic, all but the last `depth` from a transient-local one.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub before_join: u64,
    /// A subscription that joined late ([`Subscription::set_joins_at`]), once it has: how
    /// many messages published before it joined it received (a transient-local topic's
    /// history; 0 from a volatile one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub history_on_join: Option<u64>,
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

impl TopicStats {
    /// The value of QoS counter `c`.
    pub fn counter(&self, c: QosCounter) -> u64 {
        match c {
            QosCounter::Expired => self.expired,
            QosCounter::Refused => self.refused,
            QosCounter::Lost => self.lost,
            QosCounter::Retransmitted => self.retransmitted,
            QosCounter::OfferedDeadlineMissed => self.offered_deadline_missed,
            QosCounter::RequestedDeadlineMissed => self.requested_deadline_missed,
        }
    }

    /// The QoS counters a topic whose latest stats these are reports, in output order:
    /// those enabled by any of `qos` (e.g. its QoS at the start and at the end of a run),
    /// or nonzero here.
    pub fn reported(&self, qos: &[TopicQos]) -> Vec<QosCounter> {
        QosCounter::ALL
            .into_iter()
            .filter(|&c| qos.iter().any(|q| c.enabled_by(q)) || self.counter(c) > 0)
            .collect()
    }
}

/// Why a depth cannot be set.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
#[error("queue depth must be at least 1")]
pub struct ZeroDepth;

/// Deadline periods missed in a gap of `gap` between two messages (or between the last one
/// and an observation): a deadline timer restarted at each message fires at every whole
/// `deadline` strictly inside the gap, so a message exactly on the deadline is on time.
pub fn deadline_misses(gap: Nanos, deadline: Nanos) -> u64 {
    if gap.0 == 0 || deadline.0 == 0 {
        0
    } else {
        (gap.0 - 1) / deadline.0
    }
}

#[derive(Clone)]
struct LinkState {
    rng: rand_pcg::Pcg64,
    /// The newest arrival time scheduled: a message never overtakes an earlier one.
    last_arrival: Nanos,
}

#[derive(Clone)]
struct Inner<T> {
    buf: VecDeque<Message<T>>,
    /// Messages on the link with their arrival times (non-decreasing).
    in_flight: VecDeque<(Nanos, Message<T>)>,
    depth: usize,
    qos: TopicQos,
    /// True when `qos` is the chapter's as far as publish and read are concerned (keep
    /// last, latest, no deadline, lifespan or link).
    plain_qos: bool,
    /// True when publish and read take the pre-QoS topic's short path: `plain_qos` and
    /// nothing left on the link from an earlier QoS. That path leaves the timers (`now`,
    /// `last_publish`, `last_arrival`) as they were when it was entered: no deadline needs
    /// them meanwhile, and [`Inner::timers`] derives them when one does.
    plain: bool,
    /// `next_seq` when the short path was last entered: a message published since arrived
    /// at its stamp (keep last, no link: every publish is admitted at once).
    plain_from_seq: u64,
    /// The latest read time on the short path (the read's part of `now` there).
    last_read: Nanos,
    link_seed: u64,
    link: Option<LinkState>,
    next_seq: u64,
    /// Newest `seq` a subscriber has seen; `None` before the first read.
    read_high_water: Option<u64>,
    published: u64,
    dropped: u64,
    seen: u64,
    stale_reads: u64,
    expired: u64,
    refused: u64,
    lost: u64,
    retransmitted: u64,
    offered_missed: u64,
    requested_missed: u64,
    /// False while the subscription's requested QoS is incompatible with the offered: a
    /// publish is counted (by the publisher) but never reaches the queue.
    matched: bool,
    unmatched: u64,
    /// Messages published before the subscription came into being that it never received.
    before_join: u64,
    /// When the subscription comes into being (its node joins late); `None`: from t = 0.
    /// Before it, nothing is delivered: a transient-local topic keeps its last `depth`
    /// messages for it (they arrive as it joins), a volatile one keeps none.
    joins_at: Option<Nanos>,
    /// Messages it found kept for it when it joined (transient local); `None` before.
    joined_with: Option<u64>,
    last_stamp: Nanos,
    /// When the publisher last published (the offered deadline's timer; 0 at the start).
    last_publish: Nanos,
    /// When a message last arrived at the subscriber (the requested deadline's timer).
    last_arrival: Nanos,
    /// The latest `now` any operation brought (on the short path: see [`Inner::timers`]).
    now: Nanos,
}

/// See `Inner::plain`.
fn is_plain(q: &TopicQos) -> bool {
    q.history == History::KeepLast
        && q.delivery == Delivery::Latest
        && q.deadline.is_none()
        && q.lifespan.is_none()
        && q.link.is_none()
}

impl<T> Inner<T> {
    /// `(now, last_publish, last_arrival)` as updating them at every operation would have
    /// kept them. Off the short path they are the fields. On it they are the fields as the
    /// path was entered, brought up to date with what it did since: `last_stamp` is the
    /// newest publish, which arrived at its stamp if it was published on the short path, and
    /// `last_read` the latest read there. Both are times of operations that happened, so
    /// taking them into a maximum never overshoots; and the newest publish is the latest
    /// because a graph's topic has one publisher, whose stamps (its node's clock) never
    /// decrease (were they to, a deadline switched on would count from the newest publish
    /// rather than the latest).
    fn timers(&self) -> (Nanos, Nanos, Nanos) {
        if !self.plain {
            return (self.now, self.last_publish, self.last_arrival);
        }
        let arrival = if self.next_seq != self.plain_from_seq {
            self.last_arrival.max(self.last_stamp)
        } else {
            self.last_arrival
        };
        (
            self.now.max(self.last_stamp).max(self.last_read),
            self.last_publish.max(self.last_stamp),
            arrival,
        )
    }

    /// Take the short path when the QoS allows it and the link is empty; leave it
    /// otherwise, with the timers brought up to date first.
    fn choose_path(&mut self) {
        let plain =
            self.plain_qos && self.in_flight.is_empty() && self.matched && self.joins_at.is_none();
        if plain == self.plain {
            return;
        }
        if self.plain {
            (self.now, self.last_publish, self.last_arrival) = self.timers();
        } else {
            self.plain_from_seq = self.next_seq;
        }
        self.plain = plain;
    }

    fn unseen(&self, seq: u64) -> bool {
        self.read_high_water.is_none_or(|hw| seq > hw)
    }

    /// Index of the first unseen buffered message (buffers are in `seq` order). The ends
    /// are checked first: with everything or nothing buffered seen (always so at depth 1)
    /// there is nothing to search.
    #[inline]
    fn first_unseen(&self) -> usize {
        let Some(hw) = self.read_high_water else {
            return 0;
        };
        match (self.buf.front(), self.buf.back()) {
            (Some(first), _) if first.seq > hw => 0,
            (_, Some(last)) if last.seq <= hw => self.buf.len(),
            _ => self.buf.partition_point(|m| m.seq <= hw),
        }
    }

    fn evict_oldest(&mut self) {
        if let Some(old) = self.buf.pop_front() {
            if self.unseen(old.seq) {
                self.dropped += 1;
            }
        }
    }

    /// A message published before the subscription exists ([`Inner::joins_at`]; judged by
    /// its publish stamp, as a volatile publisher sends nothing to a reader not yet there,
    /// even when the message lands after it joins): kept as the
    /// publisher's history when the topic is transient local (its last `depth`; what falls
    /// out of it was never delivered), else not delivered at all. True when it is kept.
    fn keep_for_late_joiner(&mut self) -> bool {
        if self.qos.durability != crate::qos::compat::Durability::TransientLocal {
            self.before_join += 1;
            return false;
        }
        if self.buf.len() >= self.depth && self.buf.pop_front().is_some() {
            self.before_join += 1;
        }
        true
    }

    /// The subscription comes into being at `now` when it is due to: what it finds kept
    /// for it is counted once.
    fn join(&mut self, now: Nanos) {
        if self.joined_with.is_none() && self.joins_at.is_some_and(|j| now >= j) {
            self.joined_with = Some(self.buf.len() as u64);
        }
    }

    /// A message reaches the subscriber's queue at `at`, under the history rule.
    fn arrive(&mut self, at: Nanos, msg: Message<T>) {
        if self.admit(at, msg.stamp) {
            self.buf.push_back(msg);
        }
    }

    /// The deadline and history accounting of a message arriving at `at`: true when it is
    /// to be queued (room was made under the history rule), false when a full keep-all
    /// queue refused it. Split from [`Inner::arrive`] so that a publish without a link
    /// builds its message in the queue itself (the chapter's topic's hot path).
    #[inline(always)]
    fn admit(&mut self, at: Nanos, stamp: Nanos) -> bool {
        if self.joins_at.is_some_and(|j| stamp < j) {
            return self.keep_for_late_joiner();
        }
        if let Some(d) = self.qos.deadline {
            self.requested_missed += deadline_misses(at.saturating_sub(self.last_arrival), d);
        }
        self.last_arrival = self.last_arrival.max(at);
        match self.qos.history {
            History::KeepLast => {
                if self.buf.len() >= self.depth {
                    self.evict_oldest();
                }
            }
            History::KeepAll => {
                // Read messages make room; unread ones are never discarded.
                while self.buf.len() >= self.depth
                    && self.buf.front().is_some_and(|m| !self.unseen(m.seq))
                {
                    self.buf.pop_front();
                }
                if self.buf.len() >= self.depth {
                    self.refused += 1;
                    return false;
                }
            }
        }
        true
    }

    /// Bring the topic to `now`: deliver what the link has carried by then, discard what
    /// has outlived the lifespan. With nothing on the link and no lifespan (the chapter's
    /// topic) there is nothing to do but note the time.
    #[inline]
    fn settle(&mut self, now: Nanos) {
        self.now = self.now.max(now);
        if self.in_flight.is_empty() && self.qos.lifespan.is_none() {
            return;
        }
        self.deliver_and_expire(now);
    }

    /// [`Inner::settle`]'s work when there is a link or a lifespan.
    #[inline(never)]
    fn deliver_and_expire(&mut self, now: Nanos) {
        while self.in_flight.front().is_some_and(|(at, _)| *at <= now) {
            if let Some((at, msg)) = self.in_flight.pop_front() {
                self.arrive(at, msg);
            }
        }
        if let Some(life) = self.qos.lifespan {
            while self
                .buf
                .front()
                .is_some_and(|m| now.saturating_sub(m.stamp) > life)
            {
                if let Some(old) = self.buf.pop_front() {
                    if self.unseen(old.seq) {
                        self.expired += 1;
                    }
                }
            }
        }
    }

    /// Send `msg` over `link`: `None` when it is lost, else its arrival time. Kept out of
    /// line: only a topic with a link calls it.
    #[inline(never)]
    fn send(&mut self, link: Link, stamp: Nanos) -> Option<Nanos> {
        let reliable = self.qos.reliability == Reliability::Reliable;
        let seed = self.link_seed;
        let st = self.link.get_or_insert_with(|| LinkState {
            rng: rand_pcg::Pcg64::new(u128::from(seed), 0x6c69_6e6b), // "link"
            last_arrival: Nanos::ZERO,
        });
        let lose = Bernoulli::new(link.loss.clamp(0.0, 1.0)).ok()?;
        let mut sent_at = stamp;
        let mut attempts = 1;
        while lose.sample(&mut st.rng) {
            if !reliable || attempts >= MAX_ATTEMPTS {
                self.lost += 1;
                return None;
            }
            attempts += 1;
            self.retransmitted += 1;
            sent_at = sent_at.saturating_add(link.retransmit);
        }
        let j = i64::try_from(link.jitter.0).unwrap_or(i64::MAX);
        let offset = if j > 0 {
            Uniform::new_inclusive(-j, j).map_or(0, |u| u.sample(&mut st.rng))
        } else {
            0
        };
        let delay = Nanos(link.delay.0.saturating_add_signed(offset));
        let at = sent_at.saturating_add(delay).max(st.last_arrival);
        st.last_arrival = at;
        Some(at)
    }
}

/// One counter per topic of a graph, side by side, where the topics' queues count their
/// changes ([`Subscription::watch_changes`]): a watcher reads thousands of them in one pass
/// over contiguous memory instead of visiting each topic.
#[derive(Clone, Debug)]
pub struct ChangeBoard(Arc<[AtomicU64]>);

impl ChangeBoard {
    /// `n` counters at zero.
    pub fn new(n: usize) -> Self {
        Self((0..n).map(|_| AtomicU64::new(0)).collect())
    }

    /// Counter `i`, to hand to a queue (`None` past the end).
    pub fn slot(&self, i: usize) -> Option<ChangeSlot> {
        (i < self.0.len()).then(|| ChangeSlot {
            board: self.clone(),
            index: i,
        })
    }

    /// Every counter's count, in order.
    #[inline]
    pub fn counts(&self) -> impl Iterator<Item = u64> + '_ {
        self.0.iter().map(|c| c.load(Ordering::Relaxed))
    }
}

/// One counter of a [`ChangeBoard`].
#[derive(Clone, Debug)]
pub struct ChangeSlot {
    board: ChangeBoard,
    index: usize,
}

impl ChangeSlot {
    fn bump(&self) {
        // Relaxed: the watcher (the actuator) reads the count without the queue's lock. A
        // change that happened before its step by way of anything it synchronizes with (its
        // input's lock, the scheduler's hand-off, a process's lockstep) is seen; one made at
        // the same moment on another thread under the real clock may be seen a step late,
        // as reading the counters themselves at that moment would.
        self.board.0[self.index].fetch_add(1, Ordering::Relaxed);
    }
}

/// A [`Subscription`]'s queue, locked to be read only ([`Subscription::peek`]).
struct Peek<'a, T>(MutexGuard<'a, Inner<T>>);

impl<T> std::ops::Deref for Peek<'_, T> {
    type Target = Inner<T>;
    fn deref(&self) -> &Inner<T> {
        &self.0
    }
}

/// A [`Subscription`]'s state at an instant ([`Subscription::save`]).
#[derive(Clone)]
pub struct TopicState<T>(Inner<T>);

/// One subscription's queue of a topic of `T` messages, bounded to `depth` buffered
/// messages (ROS 2's subscription with its QoS; the chapter's `Topic`). Publishers and the
/// subscriber may live on different threads; every operation takes one short lock.
pub struct Subscription<T> {
    name: String,
    inner: Mutex<Inner<T>>,
    /// Where operations that may change the queue are counted, once someone watches
    /// ([`Subscription::watch_changes`]); unwatched, nothing is counted.
    changes: OnceLock<ChangeSlot>,
    /// The taps, in the order they were added (none: the lock is never made).
    taps: OnceLock<Mutex<Vec<Tap<T>>>>,
    /// Where its publisher's frames may be drawn ([`Subscription::set_lender`]).
    lender: OnceLock<Arc<dyn crate::pixels::Lender>>,
}

impl<T: Clone> Subscription<T> {
    /// A topic named `name` (by convention `/obs`, `/action`) holding at most `depth`
    /// messages, with the chapter's QoS (keep-last, latest, nothing else).
    ///
    /// # Errors
    /// [`ZeroDepth`] when `depth` is 0.
    pub fn new(name: impl Into<String>, depth: usize) -> Result<Self, ZeroDepth> {
        Self::with_qos(name, depth, TopicQos::default(), 0)
    }

    /// A topic with `qos`; `link_seed` seeds its link's losses and jitter (same seed, same
    /// fates: a virtual run with a lossy link stays byte-identical).
    ///
    /// # Errors
    /// [`ZeroDepth`] when `depth` is 0.
    pub fn with_qos(
        name: impl Into<String>,
        depth: usize,
        qos: TopicQos,
        link_seed: u64,
    ) -> Result<Self, ZeroDepth> {
        if depth == 0 {
            return Err(ZeroDepth);
        }
        Ok(Self {
            name: name.into(),
            inner: Mutex::new(Inner {
                buf: VecDeque::with_capacity(depth.min(1024)),
                in_flight: VecDeque::new(),
                depth,
                qos,
                plain_qos: is_plain(&qos),
                plain: is_plain(&qos),
                plain_from_seq: 0,
                last_read: Nanos::ZERO,
                link_seed,
                link: None,
                next_seq: 0,
                read_high_water: None,
                published: 0,
                dropped: 0,
                seen: 0,
                stale_reads: 0,
                expired: 0,
                refused: 0,
                lost: 0,
                retransmitted: 0,
                offered_missed: 0,
                requested_missed: 0,
                matched: true,
                unmatched: 0,
                before_join: 0,
                joins_at: None,
                joined_with: None,
                last_stamp: Nanos::ZERO,
                last_publish: Nanos::ZERO,
                last_arrival: Nanos::ZERO,
                now: Nanos::ZERO,
            }),
            changes: OnceLock::new(),
            taps: OnceLock::new(),
            lender: OnceLock::new(),
        })
    }

    /// The queue's whole state now (messages buffered and on the link, depth, QoS, link
    /// generator, counters and timers), for a capture of the run (`ratelab::runcore`). Its
    /// name and taps are not state: they stay as they are.
    pub fn save(&self) -> TopicState<T> {
        TopicState(self.peek().clone())
    }

    /// Put back what [`Subscription::save`] gave: the queue is as it was then.
    pub fn load(&self, state: &TopicState<T>) {
        self.lock().clone_from(&state.0);
    }

    /// Tell `tap` of every message published from now on, after the taps added before it.
    pub fn add_tap(&self, tap: Tap<T>) {
        self.taps
            .get_or_init(|| Mutex::new(Vec::new()))
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(tap);
    }

    /// Lend its publisher's frames from `lender` from now on (a launch's process lends
    /// buffers of its shared-memory pool for a topic that crosses to another): false, and
    /// nothing changed, when a lender was set before.
    pub fn set_lender(&self, lender: Arc<dyn crate::pixels::Lender>) -> bool {
        self.lender.set(lender).is_ok()
    }

    /// The lender of its publisher's frames, if one was set ([`Subscription::set_lender`]).
    pub fn lender(&self) -> Option<&Arc<dyn crate::pixels::Lender>> {
        self.lender.get()
    }

    /// Tell every tap of `msg` (nothing to do, and no lock taken, without one).
    fn tell_taps(&self, msg: &Message<T>) {
        if let Some(taps) = self.taps.get() {
            for tap in taps.lock().unwrap_or_else(|e| e.into_inner()).iter() {
                tap(msg);
            }
        }
    }

    /// The topic's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The queue, to change it: counted in its [`ChangeSlot`], if watched.
    fn lock(&self) -> MutexGuard<'_, Inner<T>> {
        // A panic elsewhere cannot leave the buffer half-updated (every update is a
        // single push/pop plus counters), so a poisoned lock is still consistent. Counted
        // under the lock, before the change is made.
        let inner = self.inner.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(slot) = self.changes.get() {
            slot.bump();
        }
        inner
    }

    /// The queue, to read it only (never counted as a change).
    fn peek(&self) -> Peek<'_, T> {
        Peek(self.inner.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Count from now on, in `slot`, every operation that may change the queue or its
    /// counters (publish, read, arrival, QoS, depth, load, …), never one that only looks:
    /// equal counts at two moments mean equal [`Subscription::stats_at`] at equal `now`
    /// (with a deadline the counters also move with `now` alone). What lets the actuator's
    /// step record skip a topic that did nothing. A queue is watched once: false, and
    /// nothing changes, when it already is.
    pub fn watch_changes(&self, slot: ChangeSlot) -> bool {
        self.changes.set(slot).is_ok()
    }

    /// Publish a message at run time `stamp` (the publisher's now). Without a link it
    /// reaches the queue at once, evicting (and maybe dropping) the oldest when full, or
    /// refused by a full keep-all queue; over a link it arrives later or is lost.
    /// Returns the new message's `seq`.
    pub fn publish(&self, data: T, stamp: Nanos, origin_stamp: Option<Nanos>) -> u64 {
        let mut inner = self.lock();
        if inner.plain {
            // The chapter's topic: what the general path below does when there is no
            // deadline, lifespan or link (the timers: see `Inner::timers`).
            if inner.buf.len() >= inner.depth {
                inner.evict_oldest();
            }
            let seq = inner.next_seq;
            inner.next_seq += 1;
            inner.published += 1;
            inner.last_stamp = stamp;
            inner.buf.push_back(Message {
                data,
                stamp,
                seq,
                origin_stamp,
            });
            if let Some(msg) = inner.buf.back() {
                self.tell_taps(msg);
            }
            return seq;
        }
        inner.settle(stamp);
        inner.join(stamp);
        if let Some(d) = inner.qos.deadline {
            inner.offered_missed += deadline_misses(stamp.saturating_sub(inner.last_publish), d);
        }
        inner.last_publish = inner.last_publish.max(stamp);
        let seq = inner.next_seq;
        inner.next_seq += 1;
        inner.published += 1;
        inner.last_stamp = stamp;
        let msg = Message {
            data,
            stamp,
            seq,
            origin_stamp,
        };
        self.tell_taps(&msg);
        if !inner.matched {
            // Published, and told to the taps (the publisher did publish it), but never
            // connected to this subscription.
            inner.unmatched += 1;
            return seq;
        }
        match inner.qos.link {
            None => {
                if inner.admit(stamp, stamp) {
                    inner.buf.push_back(msg);
                }
            }
            Some(link) => match inner.send(link, stamp) {
                None => {}
                Some(at) if at <= stamp && inner.in_flight.is_empty() => inner.arrive(stamp, msg),
                Some(at) => inner.in_flight.push_back((at, msg)),
            },
        }
        if inner.plain_qos {
            inner.choose_path();
        }
        seq
    }

    /// Read at run time `now`, by the topic's delivery: the newest message (latest; moves
    /// the read high-water mark past everything buffered) or the oldest unread one (FIFO).
    /// With nothing new it returns the last message read again (a *stale read*); `None`
    /// when nothing is buffered (nothing published yet, or all of it expired).
    pub fn read(&self, now: Nanos) -> Option<Message<T>> {
        let mut inner = self.lock();
        if inner.plain {
            // The chapter's latest-wins read: the general path below, for no lifespan, no
            // link and latest delivery. The buffer is in `seq` order, so it is stale exactly
            // when its newest message is at or below the high-water mark.
            inner.last_read = inner.last_read.max(now);
            let newest = inner.buf.back()?.clone();
            match inner.read_high_water {
                Some(hw) if newest.seq <= hw => inner.stale_reads += 1,
                hw => {
                    // Everything buffered above the mark is seen now: at depth 1 (the
                    // chapter's topic) the one message, without a search.
                    let len = inner.buf.len();
                    let unseen = if len == 1 || hw.is_none() {
                        len
                    } else {
                        len - inner.first_unseen()
                    };
                    inner.seen += unseen as u64;
                    inner.read_high_water = Some(newest.seq);
                }
            }
            return Some(newest);
        }
        inner.settle(now);
        inner.join(now);
        if inner.plain_qos {
            inner.choose_path();
        }
        let first_unseen = inner.first_unseen();
        let pick = match inner.qos.delivery {
            _ if first_unseen >= inner.buf.len() => {
                inner.stale_reads += u64::from(!inner.buf.is_empty());
                return inner.buf.back().cloned();
            }
            Delivery::Latest => {
                inner.seen += (inner.buf.len() - first_unseen) as u64;
                inner.buf.len() - 1
            }
            Delivery::Fifo => {
                inner.seen += 1;
                first_unseen
            }
        };
        let msg = inner.buf[pick].clone();
        inner.read_high_water = Some(inner.read_high_water.map_or(msg.seq, |hw| hw.max(msg.seq)));
        Some(msg)
    }

    /// Change the history depth while running. Shrinking keeps the newest messages and
    /// evicts the oldest under the same drop rule as [`Subscription::publish`].
    ///
    /// # Errors
    /// [`ZeroDepth`] when `depth` is 0 (the topic is unchanged).
    pub fn set_depth(&self, depth: usize) -> Result<(), ZeroDepth> {
        if depth == 0 {
            return Err(ZeroDepth);
        }
        let mut inner = self.lock();
        inner.depth = depth;
        while inner.buf.len() > depth {
            inner.evict_oldest();
        }
        Ok(())
    }

    /// The QoS in force.
    pub fn qos(&self) -> TopicQos {
        self.peek().qos
    }

    /// Change the QoS while running (the lab's keys). Messages already on the link keep
    /// their arrival times; the deadline timers keep running from the last message (a
    /// deadline switched on counts from the last publish and the last arrival, whatever
    /// QoS they were under).
    pub fn set_qos(&self, qos: TopicQos) {
        let mut inner = self.lock();
        inner.qos = qos;
        inner.plain_qos = is_plain(&qos);
        inner.choose_path();
    }

    /// Connect the subscription to its publisher (`true`, as it starts) or leave it
    /// unconnected (`false`: its requested QoS is incompatible with the offered,
    /// [`crate::qos::compat`]). While unconnected, every publish is counted `unmatched` and
    /// never reaches the queue; what was buffered before stays readable.
    pub fn set_matched(&self, matched: bool) {
        let mut inner = self.lock();
        inner.matched = matched;
        inner.choose_path();
    }

    /// Make the subscription come into being at run time `at` (its node joins the graph
    /// late, ROS 2's *late joiner*): before it nothing is delivered; a transient-local topic
    /// keeps its last `depth` messages for it, which it finds as it joins
    /// ([`TopicStats::history_on_join`]), and a volatile one keeps none. Its requested
    /// deadline counts from `at`. Set before the run starts.
    pub fn set_joins_at(&self, at: Nanos) {
        let mut inner = self.lock();
        inner.joins_at = Some(at);
        inner.last_arrival = inner.last_arrival.max(at);
        inner.choose_path();
    }

    /// The topic's publisher comes into being at run time `at` (its node joins late): its
    /// offered deadline counts from then, not from t = 0. Set before the run starts.
    pub fn set_publisher_start(&self, at: Nanos) {
        let mut inner = self.lock();
        inner.last_publish = inner.last_publish.max(at);
    }

    /// Whether the subscription is connected to its publisher ([`Subscription::set_matched`]).
    pub fn matched(&self) -> bool {
        self.peek().matched
    }

    /// Counters and depth as of the topic's latest operation.
    pub fn stats(&self) -> TopicStats {
        let now = self.peek().timers().0;
        self.stats_at(now)
    }

    /// Counters and depth at run time `now`, read together under one lock, without changing
    /// the topic: deadline periods missed up to `now` count even before the next message
    /// (ROS 2's deadline timer fires without one).
    pub fn stats_at(&self, now: Nanos) -> TopicStats {
        self.stats_and_timing_at(now).0
    }

    /// [`Subscription::stats_at`], and whether the counters move with `now` alone (a
    /// deadline, whose missed periods count without any operation), read under one lock.
    pub fn stats_and_timing_at(&self, now: Nanos) -> (TopicStats, bool) {
        let inner = self.peek();
        let (mut offered, mut requested) = (inner.offered_missed, inner.requested_missed);
        if let Some(d) = inner.qos.deadline {
            offered += deadline_misses(now.saturating_sub(inner.last_publish), d);
            // Arrivals due by `now` that no operation has delivered yet still reset the timer.
            let mut last = inner.last_arrival;
            for (at, _) in inner.in_flight.iter().take_while(|(at, _)| *at <= now) {
                requested += deadline_misses(at.saturating_sub(last), d);
                last = last.max(*at);
            }
            requested += deadline_misses(now.saturating_sub(last), d);
        }
        let stats = TopicStats {
            published: inner.published,
            dropped: inner.dropped,
            seen: inner.seen,
            stale_reads: inner.stale_reads,
            last_stamp: inner.last_stamp,
            depth: inner.depth,
            expired: inner.expired,
            refused: inner.refused,
            lost: inner.lost,
            retransmitted: inner.retransmitted,
            in_flight: inner.in_flight.len() as u64,
            offered_deadline_missed: offered,
            requested_deadline_missed: requested,
            unmatched: inner.unmatched,
            before_join: inner.before_join,
            history_on_join: inner.joined_with,
        };
        (stats, inner.qos.deadline.is_some())
    }

    /// When the last message arrived at the subscriber (0 before the first), for a deadline
    /// reaction: the actuator compares it with its deadline.
    pub fn last_arrival(&self) -> Nanos {
        self.peek().timers().2
    }

    /// Buffered messages no subscriber has seen yet.
    pub fn unseen_buffered(&self) -> usize {
        let inner = self.peek();
        inner.buf.len() - inner.first_unseen()
    }

    /// Messages currently buffered (≤ depth).
    pub fn buffered(&self) -> usize {
        self.peek().buf.len()
    }

    /// The newest buffered message, without reading it (the read high-water mark, and so
    /// the drop count, is unchanged). For onlookers.
    pub fn peek_newest(&self) -> Option<Message<T>> {
        self.peek().buf.back().cloned()
    }

    /// The sequence number the next publish will take (= messages published so far, with
    /// any [`Subscription::count_lost`]).
    pub fn next_seq(&self) -> u64 {
        self.peek().next_seq
    }

    /// Account `n` messages published elsewhere that never reached this copy of the topic
    /// (a gap in the sequence numbers arriving over the wire, `ratelab::distributed`): they
    /// count as published and `lost`, and take their sequence numbers, so the next message
    /// keeps its publisher's `seq` and `published = seen + dropped + … + lost` still holds.
    pub fn count_lost(&self, n: u64) {
        let mut inner = self.lock();
        inner.next_seq = inner.next_seq.saturating_add(n);
        inner.published = inner.published.saturating_add(n);
        inner.lost = inner.lost.saturating_add(n);
    }

    /// The buffered messages with `seq >= from`, oldest first, without reading them: the read
    /// high-water mark, and so the drop count, is unchanged. For onlookers such as a recorder.
    pub fn peek_from(&self, from: u64) -> Vec<Message<T>> {
        self.peek()
            .buf
            .iter()
            .filter(|m| m.seq >= from)
            .cloned()
            .collect()
    }
}

impl<T> std::fmt::Debug for Subscription<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Subscription")
            .field("name", &self.name)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_watched_queue_counts_what_changes_it_and_never_what_only_looks() {
        let topic = t(2);
        let board = ChangeBoard::new(2);
        assert!(topic.watch_changes(board.slot(1).unwrap()));
        assert!(!topic.watch_changes(board.slot(0).unwrap()), "watched once");
        assert!(board.slot(2).is_none());
        let count = || board.counts().nth(1).unwrap();
        let mut last = count();
        let mut moved = |what: &str, expect: bool| {
            let now = count();
            assert_eq!(now != last, expect, "{what}");
            last = now;
        };
        topic.publish(1, Nanos(10), None);
        moved("publish", true);
        let saved = topic.save();
        let _ = (
            topic.stats(),
            topic.stats_at(Nanos(99)),
            topic.qos(),
            topic.matched(),
        );
        let _ = (
            topic.buffered(),
            topic.unseen_buffered(),
            topic.peek_newest(),
        );
        let _ = (topic.next_seq(), topic.peek_from(0), topic.last_arrival());
        moved("looking", false);
        topic.read(Nanos(20));
        moved("read", true);
        topic.set_depth(1).unwrap();
        moved("depth", true);
        topic.set_qos(TopicQos::default());
        moved("qos", true);
        topic.set_matched(true);
        moved("matched", true);
        topic.count_lost(1);
        moved("lost", true);
        topic.load(&saved);
        moved("load", true);
        assert_eq!(board.counts().next(), Some(0), "the other slot never moved");
    }

    #[test]
    fn a_tap_is_told_of_every_message_published_even_those_later_dropped() {
        let topic = t(1);
        let seen = std::sync::Arc::new(Mutex::new(Vec::new()));
        let s = seen.clone();
        topic.add_tap(Box::new(move |m: &Message<u32>| {
            s.lock().unwrap().push((m.seq, m.data, m.stamp))
        }));
        // A second tap is told too, after the first.
        let second = std::sync::Arc::new(Mutex::new(0u32));
        let n = second.clone();
        topic.add_tap(Box::new(move |_| *n.lock().unwrap() += 1));
        for i in 0..3 {
            topic.publish(10 + i, Nanos(u64::from(i)), None);
        }
        assert_eq!(topic.stats().dropped, 2);
        assert_eq!(*second.lock().unwrap(), 3, "every tap sees every message");
        let lossy = Subscription::with_qos(
            "/l",
            1,
            TopicQos {
                deadline: Some(Nanos(5)),
                ..TopicQos::default()
            },
            0,
        )
        .unwrap();
        let s = seen.clone();
        lossy.add_tap(Box::new(move |m: &Message<u32>| {
            s.lock().unwrap().push((m.seq, m.data, m.stamp))
        }));
        lossy.publish(7, Nanos(9), None);
        assert_eq!(
            *seen.lock().unwrap(),
            [
                (0, 10, Nanos(0)),
                (1, 11, Nanos(1)),
                (2, 12, Nanos(2)),
                (0, 7, Nanos(9))
            ]
        );
    }

    /// The tests of the chapter's rule read at any time: without lifespan or link, time
    /// does not matter.
    const NOW: Nanos = Nanos(1_000);

    fn t(depth: usize) -> Subscription<u32> {
        Subscription::new("/t", depth).unwrap()
    }

    #[test]
    fn depth_one_drops_every_unread_superseded_message() {
        let topic = t(1);
        topic.publish(0, Nanos(0), None);
        topic.publish(1, Nanos(1), None); // 0 evicted unread
        topic.publish(2, Nanos(2), None); // 1 evicted unread
        assert_eq!(topic.stats().dropped, 2);
        assert_eq!(topic.read(NOW).unwrap().data, 2);
        topic.publish(3, Nanos(3), None); // 2 was read: not a drop
        assert_eq!(topic.stats().dropped, 2);
        assert_eq!(topic.stats().published, 4);
    }

    #[test]
    fn peeking_is_not_reading() {
        let topic = t(2);
        topic.publish(0, Nanos(0), None);
        topic.publish(1, Nanos(1), None);
        let seen: Vec<u32> = topic.peek_from(1).into_iter().map(|m| m.data).collect();
        assert_eq!(seen, [1]);
        assert_eq!(topic.peek_from(0).len(), 2);
        topic.publish(2, Nanos(2), None); // 0 evicted: never read, peeking does not count
        assert_eq!(topic.stats().dropped, 1);
        assert!(topic.peek_from(3).is_empty());
    }

    #[test]
    fn nothing_published_reads_none() {
        assert!(t(3).read(NOW).is_none());
        assert_eq!(t(3).stats().dropped, 0);
    }

    #[test]
    fn deep_queue_absorbs_until_full() {
        let topic = t(3);
        for i in 0..3 {
            topic.publish(i, Nanos(i as u64), None);
        }
        assert_eq!(topic.stats().dropped, 0);
        topic.publish(3, Nanos(3), None); // evicts 0, unread
        assert_eq!(topic.stats().dropped, 1);
        // Reading the newest marks everything buffered as seen.
        assert_eq!(topic.read(NOW).unwrap().seq, 3);
        for i in 4..7 {
            topic.publish(i, Nanos(i as u64), None); // evicts 1, 2, 3: all seen
        }
        assert_eq!(topic.stats().dropped, 1);
        topic.publish(7, Nanos(7), None); // evicts 4: unread
        assert_eq!(topic.stats().dropped, 2);
    }

    #[test]
    fn reading_between_publishes_prevents_all_drops() {
        let topic = t(1);
        for i in 0..100 {
            topic.publish(i, Nanos(i as u64), None);
            assert_eq!(topic.read(NOW).unwrap().data, i);
        }
        assert_eq!(
            topic.stats(),
            TopicStats {
                published: 100,
                dropped: 0,
                seen: 100,
                stale_reads: 0,
                last_stamp: Nanos(99),
                depth: 1,
                ..TopicStats::default()
            }
        );
    }

    #[test]
    fn shrinking_depth_keeps_newest_and_counts_unread_evictions() {
        let topic = t(5);
        for i in 0..5 {
            topic.publish(i, Nanos(i as u64), None);
        }
        topic.set_depth(2).unwrap(); // evicts 0, 1, 2 unread
        assert_eq!(topic.stats().dropped, 3);
        assert_eq!(topic.buffered(), 2);
        assert_eq!(topic.read(NOW).unwrap().data, 4);
        topic.set_depth(1).unwrap(); // evicts 3: it was below the high-water mark (read past)
        assert_eq!(topic.stats().dropped, 3);
        // Growing keeps everything and the rule stays exact.
        topic.set_depth(3).unwrap();
        topic.publish(5, Nanos(5), None);
        topic.publish(6, Nanos(6), None);
        assert_eq!(topic.stats().dropped, 3);
        topic.publish(7, Nanos(7), None); // evicts 4 (read)
        assert_eq!(topic.stats().dropped, 3);
        topic.publish(8, Nanos(8), None); // evicts 5 (unread)
        assert_eq!(topic.stats().dropped, 4);
        assert_eq!(topic.set_depth(0), Err(ZeroDepth));
        assert!(Subscription::<u8>::new("/z", 0).is_err());
    }

    #[test]
    fn stale_reads_are_the_mirror_of_drops() {
        // A publisher at a fifth of the subscriber's rate: each message is read five times.
        let topic = t(1);
        assert!(topic.read(NOW).is_none());
        assert_eq!(
            topic.stats().stale_reads,
            0,
            "nothing to read is not a stale read"
        );
        for i in 0..3 {
            topic.publish(i, Nanos(u64::from(i) * 5), None);
            for _ in 0..5 {
                assert_eq!(topic.read(NOW).unwrap().data, i);
            }
        }
        let s = topic.stats();
        assert_eq!((s.stale_reads, s.dropped, s.seen), (12, 0, 3));
        assert_eq!(s.last_stamp, Nanos(10));
    }

    #[test]
    fn every_message_is_seen_dropped_or_waiting() {
        let topic = t(3);
        let account = |t: &Subscription<u32>| {
            let s = t.stats();
            assert_eq!(
                s.published,
                s.seen + s.dropped + t.unseen_buffered() as u64,
                "{s:?}"
            );
        };
        for i in 0..5 {
            topic.publish(i, Nanos(u64::from(i)), None);
            account(&topic);
        }
        topic.read(NOW); // sees 2, 3, 4
        assert_eq!(topic.stats().seen, 3);
        account(&topic);
        topic.publish(5, Nanos(5), None);
        topic.set_depth(1).unwrap(); // evicts 3, 4 (seen)
        account(&topic);
        topic.read(NOW);
        topic.read(NOW); // nothing new to see
        assert_eq!(topic.stats().seen, 4);
        account(&topic);
    }

    #[test]
    fn messages_carry_stamps_and_origin() {
        let topic = t(2);
        topic.publish(9, Nanos(40), Some(Nanos(20)));
        let m = topic.read(NOW).unwrap();
        assert_eq!(
            (m.stamp, m.seq, m.origin_stamp),
            (Nanos(40), 0, Some(Nanos(20)))
        );
    }

    // ---- QoS ----------------------------------------------------------------------------

    use crate::qos::{apply_key, split_pairs};

    fn q(depth: usize, pairs: &str) -> Subscription<u32> {
        let mut qos = TopicQos::default();
        let mut d = depth;
        for (k, v) in split_pairs(pairs).unwrap() {
            apply_key(&mut qos, &mut d, k, v).unwrap();
        }
        Subscription::with_qos("/q", d, qos, 7).unwrap()
    }

    fn ms(v: u64) -> Nanos {
        Nanos::from_millis(v)
    }

    /// published = seen + dropped + expired + lost + refused + unseen buffered + in flight.
    fn accounted(t: &Subscription<u32>) {
        let s = t.stats();
        assert_eq!(
            s.published,
            s.seen
                + s.dropped
                + s.expired
                + s.lost
                + s.refused
                + t.unseen_buffered() as u64
                + s.in_flight,
            "{s:?}"
        );
    }

    #[test]
    fn fifo_hands_out_the_oldest_unread_one_at_a_time() {
        let topic = q(100, "delivery=fifo");
        for i in 0..5 {
            topic.publish(i, ms(u64::from(i) * 20), Some(ms(u64::from(i) * 20)));
        }
        let got: Vec<u32> = (0..5).map(|_| topic.read(ms(100)).unwrap().data).collect();
        assert_eq!(got, [0, 1, 2, 3, 4]);
        let s = topic.stats();
        assert_eq!((s.seen, s.dropped, s.stale_reads), (5, 0, 0));
        assert_eq!(
            topic.read(ms(100)).unwrap().data,
            4,
            "nothing new: the last one again"
        );
        assert_eq!(topic.stats().stale_reads, 1);
        accounted(&topic);
    }

    #[test]
    fn fifo_behind_a_fast_publisher_falls_ever_further_behind() {
        // The stale queue: 50 Hz in, 10 Hz out, depth 100. No drop until the queue is full,
        // and the age of what is read grows by 80 ms every read.
        let topic = q(100, "delivery=fifo");
        let mut ages = Vec::new();
        for step in 0..50u64 {
            let now = ms(step * 20);
            topic.publish(0, now, Some(now));
            if step % 5 == 0 {
                let m = topic.read(now).unwrap();
                ages.push((now - m.origin_stamp.unwrap()).0 / 1_000_000);
            }
        }
        assert_eq!(ages, [0, 80, 160, 240, 320, 400, 480, 560, 640, 720]);
        assert_eq!(topic.stats().dropped, 0);
        // The same stream under latest: the age of what is read stays 0; 4 of 5 skipped.
        let latest = q(100, "delivery=latest");
        for step in 0..50u64 {
            let now = ms(step * 20);
            latest.publish(0, now, Some(now));
            if step % 5 == 0 {
                assert_eq!(latest.read(now).unwrap().origin_stamp, Some(now));
            }
        }
        accounted(&topic);
        accounted(&latest);
    }

    #[test]
    fn keep_all_refuses_into_a_cap_full_of_unread_and_makes_room_from_read_ones() {
        let topic = q(3, "history=keep_all,delivery=fifo");
        for i in 0..5 {
            topic.publish(i, ms(u64::from(i)), None);
        }
        let s = topic.stats();
        assert_eq!(
            (s.refused, s.dropped),
            (2, 0),
            "3 and 4 refused, nothing lost silently"
        );
        assert_eq!(topic.read(ms(5)).unwrap().data, 0);
        topic.publish(5, ms(5), None); // 0 was read: it makes room
        assert_eq!(topic.stats().refused, 2);
        let rest: Vec<u32> = (0..3).map(|_| topic.read(ms(6)).unwrap().data).collect();
        assert_eq!(rest, [1, 2, 5]);
        accounted(&topic);
        // Under latest a read reads past everything, so everything makes room.
        let latest = q(2, "history=keep_all");
        for i in 0..4 {
            latest.publish(i, ms(u64::from(i)), None);
            latest.read(ms(u64::from(i)));
        }
        assert_eq!(latest.stats().refused, 0);
        accounted(&latest);
    }

    #[test]
    fn lifespan_expires_unread_messages_and_leaves_nothing_stale_to_read() {
        let topic = q(10, "lifespan_ms=50");
        topic.publish(0, ms(0), None);
        topic.publish(1, ms(20), None);
        assert_eq!(
            topic.read(ms(60)).unwrap().data,
            1,
            "0 is 60 ms old: expired"
        );
        let s = topic.stats();
        assert_eq!((s.expired, s.seen), (1, 1));
        assert_eq!(
            topic.read(ms(70)).unwrap().data,
            1,
            "exactly 50 ms old still lives"
        );
        assert_eq!(topic.stats().stale_reads, 1);
        assert!(
            topic.read(ms(71)).is_none(),
            "read and then outlived: gone, not a stale read"
        );
        let s = topic.stats();
        assert_eq!(
            (s.expired, s.stale_reads),
            (1, 1),
            "it had been read: not counted expired"
        );
        accounted(&topic);
    }

    #[test]
    fn deadline_misses_count_per_period_on_both_sides() {
        assert_eq!(
            deadline_misses(ms(40), ms(40)),
            0,
            "on the deadline is on time"
        );
        assert_eq!(deadline_misses(ms(41), ms(40)), 1);
        assert_eq!(deadline_misses(ms(100), ms(40)), 2);
        assert_eq!(deadline_misses(ms(120), ms(40)), 2);
        assert_eq!(deadline_misses(Nanos(0), ms(40)), 0);
        let topic = q(1, "deadline_ms=40");
        topic.publish(0, ms(0), None);
        topic.publish(1, ms(100), None); // a 100 ms gap: 2 periods missed
        let s = topic.stats();
        assert_eq!(
            (s.offered_deadline_missed, s.requested_deadline_missed),
            (2, 2)
        );
        // Observed before the next message: the timer has fired already.
        let s = topic.stats_at(ms(181));
        assert_eq!(
            (s.offered_deadline_missed, s.requested_deadline_missed),
            (4, 4)
        );
        topic.publish(2, ms(190), None); // the 90 ms gap missed 2: the same 4, committed
        assert_eq!(topic.stats().offered_deadline_missed, 4);
        // A live change: no deadline, no count.
        assert_eq!(
            q(1, "depth=1").stats_at(ms(1000)).offered_deadline_missed,
            0
        );
    }

    #[test]
    fn a_link_delays_and_keeps_order() {
        let topic = q(10, "delay_ms=10,jitter_ms=5");
        topic.publish(0, ms(0), None);
        assert!(topic.read(ms(4)).is_none(), "nothing arrives before 5 ms");
        assert_eq!(topic.stats().in_flight, 1);
        assert!(topic.read(ms(15)).is_some(), "everything arrives by 15 ms");
        assert_eq!(topic.stats().in_flight, 0);
        let mut last = None;
        let fifo = q(100, "delay_ms=10,jitter_ms=5,delivery=fifo");
        for i in 0..20u64 {
            fifo.publish(i as u32, ms(i * 2), None);
        }
        while let Some(m) = fifo.read(ms(100)) {
            if last == Some(m.seq) {
                break;
            }
            assert!(last.is_none_or(|l| m.seq > l), "in order");
            last = Some(m.seq);
        }
        assert_eq!(last, Some(19));
        accounted(&topic);
        accounted(&fifo);
    }

    #[test]
    fn best_effort_loses_and_reliable_retransmits() {
        let be = q(1000, "loss=0.2,delivery=fifo");
        let rel = q(
            1000,
            "loss=0.2,reliability=reliable,delivery=fifo,delay_ms=1",
        );
        for i in 0..1000u64 {
            be.publish(0, ms(i), None);
            rel.publish(0, ms(i), None);
        }
        let (b, r) = (be.stats(), rel.stats_at(ms(2000)));
        assert!((150..250).contains(&b.lost), "about 20% of 1000: {b:?}");
        assert_eq!(b.retransmitted, 0);
        assert_eq!(r.lost, 0);
        assert!(
            (200..300).contains(&r.retransmitted),
            "about 0.25 per message: {r:?}"
        );
        rel.read(ms(2000)); // everything has arrived by now
        assert_eq!(rel.stats().in_flight, 0);
        accounted(&be);
        accounted(&rel);
        // Same seed, same fates.
        let again = q(1000, "loss=0.2,delivery=fifo");
        for i in 0..1000u64 {
            again.publish(0, ms(i), None);
        }
        assert_eq!(again.stats(), be.stats());
    }

    #[test]
    fn a_deadline_switched_on_after_plain_messages_counts_from_the_last_message() {
        // The chapter's topic takes the short path, which keeps no timers per message; a
        // deadline switched on live still counts from the last publish and arrival.
        let topic = t(1);
        for i in 0..3u64 {
            topic.publish(0, ms(i * 20), None); // 0, 20, 40 ms
        }
        assert_eq!(topic.read(ms(50)).unwrap().stamp, ms(40));
        topic.set_qos(q(1, "deadline_ms=15").qos());
        assert_eq!(topic.last_arrival(), ms(40));
        // As of the last operation (the read at 50 ms): 10 ms since the last message.
        let s = topic.stats();
        assert_eq!(
            (s.offered_deadline_missed, s.requested_deadline_missed),
            (0, 0)
        );
        // At 100 ms: a 60 ms gap from the message at 40 ms misses 3 periods of 15 ms.
        let s = topic.stats_at(ms(100));
        assert_eq!(
            (s.offered_deadline_missed, s.requested_deadline_missed),
            (3, 3)
        );
        topic.publish(0, ms(100), None);
        assert_eq!(topic.stats().offered_deadline_missed, 3, "committed");
        // A read later than the last publish counts as the topic's latest time as well.
        let topic = t(1);
        topic.publish(0, ms(40), None);
        topic.read(ms(70));
        topic.set_qos(q(1, "deadline_ms=15").qos());
        assert_eq!(
            topic.stats().requested_deadline_missed,
            1,
            "30 ms: 1 period"
        );
        // A message the link lost before the QoS went plain never arrived: switched back on,
        // the requested deadline still counts from the last message that did.
        let topic = q(1, "loss=1");
        topic.publish(0, ms(10), None);
        assert_eq!(topic.stats().lost, 1);
        topic.set_qos(TopicQos::default());
        topic.set_qos(q(1, "deadline_ms=40").qos());
        assert_eq!(topic.last_arrival(), Nanos::ZERO);
        let s = topic.stats_at(ms(100));
        assert_eq!(
            (s.offered_deadline_missed, s.requested_deadline_missed),
            (2, 2)
        );
    }

    #[test]
    fn the_short_path_counts_as_the_general_one_across_live_qos_changes() {
        // The same operations on two topics: `a` with the QoS of each phase, taking the
        // short path whenever it is plain; `b` with the same QoS plus a lifespan of an hour,
        // which expires nothing here but keeps it on the general path (timers updated at
        // every operation). Every read, counter and timer must agree, at every step.
        let phases = [
            "",
            "deadline_ms=30",
            "",
            "loss=0.3,delay_ms=15,jitter_ms=5",
            "",
            "deadline_ms=25,loss=0.2,delay_ms=5,reliability=reliable",
            "depth=3",
            "deadline_ms=45",
            "",
        ];
        let qos = |pairs: &str, hour: bool| {
            let mut qos = TopicQos::default();
            let mut d = 1;
            let all = match (pairs, hour) {
                ("", false) => String::new(),
                ("", true) => "lifespan_ms=3600000".to_string(),
                (p, false) => p.to_string(),
                (p, true) => format!("{p},lifespan_ms=3600000"),
            };
            if !all.is_empty() {
                for (k, v) in split_pairs(&all).unwrap() {
                    apply_key(&mut qos, &mut d, k, v).unwrap();
                }
            }
            (qos, d)
        };
        for seed in 1..=20u64 {
            let mut x = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
            let mut rand = move |n: u64| {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                x % n
            };
            let a = Subscription::<u32>::with_qos("/a", 1, TopicQos::default(), 7).unwrap();
            let b = Subscription::<u32>::with_qos("/b", 1, qos("", true).0, 7).unwrap();
            let mut now = Nanos::ZERO;
            for (i, phase) in phases.iter().enumerate() {
                if i > 0 {
                    let ((qa, da), (qb, db)) = (qos(phase, false), qos(phase, true));
                    a.set_depth(da).unwrap();
                    b.set_depth(db).unwrap();
                    a.set_qos(qa);
                    b.set_qos(qb);
                    assert_eq!(a.qos().lifespan, None);
                    // Right after the change, before any operation.
                    let later = now.saturating_add(ms(rand(100)));
                    assert_eq!(a.stats(), b.stats(), "seed {seed} phase {phase}");
                    assert_eq!(a.stats_at(later), b.stats_at(later), "seed {seed}");
                    assert_eq!(a.last_arrival(), b.last_arrival(), "seed {seed}");
                }
                for _ in 0..rand(40) {
                    now = now.saturating_add(ms(rand(30)));
                    if rand(3) == 0 {
                        assert_eq!(a.read(now), b.read(now), "seed {seed} phase {phase}");
                    } else {
                        let v = rand(1000) as u32;
                        a.publish(v, now, Some(now));
                        b.publish(v, now, Some(now));
                    }
                    let later = now.saturating_add(ms(rand(100)));
                    assert_eq!(a.stats(), b.stats(), "seed {seed} phase {phase}");
                    assert_eq!(a.stats_at(later), b.stats_at(later), "seed {seed}");
                    assert_eq!(a.last_arrival(), b.last_arrival(), "seed {seed}");
                }
            }
            accounted(&a);
        }
    }

    #[test]
    fn a_lost_message_misses_the_requested_deadline_not_the_offered_one() {
        let topic = q(1, "loss=0.5,deadline_ms=25");
        for i in 0..200u64 {
            topic.publish(0, ms(i * 20), None);
        }
        let s = topic.stats();
        assert_eq!(
            s.offered_deadline_missed, 0,
            "the publisher kept its 20 ms period"
        );
        assert!(s.requested_deadline_missed > 20, "{s:?}");
        assert!(s.lost > 50);
    }

    /// A subscription left unconnected (its requested QoS incompatible, `crate::qos::compat`)
    /// gets nothing while the publisher goes on publishing; connected again, it gets what
    /// is published from then on. Every message stays accounted for.
    #[test]
    fn an_unmatched_subscription_receives_nothing_and_counts_it() {
        for pairs in ["depth=1", "depth=3,deadline_ms=15"] {
            let topic = q(3, pairs);
            topic.publish(1, Nanos::from_millis(0), None);
            topic.set_matched(false);
            assert!(!topic.matched());
            for i in 1..=4 {
                topic.publish(10 + i, Nanos::from_millis(10 * i as u64), None);
            }
            // What was buffered before stays readable; nothing since arrived.
            assert_eq!(topic.read(Nanos::from_millis(45)).map(|m| m.data), Some(1));
            let s = topic.stats();
            assert_eq!(
                (s.published, s.unmatched, s.seen),
                (5, 4, 1),
                "{pairs}: {s:?}"
            );
            topic.set_matched(true);
            topic.publish(99, Nanos::from_millis(50), None);
            assert_eq!(topic.read(Nanos::from_millis(55)).map(|m| m.data), Some(99));
            let s = topic.stats();
            assert_eq!(
                s.published,
                s.seen + s.dropped + s.unmatched + topic.unseen_buffered() as u64,
                "{pairs}: {s:?}"
            );
            // Captured and restored with the queue.
            let saved = topic.save();
            topic.set_matched(false);
            topic.load(&saved);
            assert!(topic.matched());
        }
    }

    /// A subscription that comes into being late (its node's `start_ms`) gets nothing
    /// published before it from a volatile topic, and the last `depth` messages from a
    /// transient-local one (ROS 2's durability); either way the rest is accounted for.
    #[test]
    fn a_late_joiner_gets_history_only_from_a_transient_local_topic() {
        for (durability, history) in [("volatile", vec![]), ("transient_local", vec![7, 8, 9])] {
            let topic = q(3, &format!("durability={durability},delivery=fifo"));
            topic.set_joins_at(Nanos::from_millis(100));
            for i in 0..10u32 {
                topic.publish(i, Nanos::from_millis(10 * u64::from(i)), None);
            }
            let got: Vec<u32> = (0..history.len().max(1))
                .filter_map(|k| {
                    topic
                        .read(Nanos::from_millis(100 + k as u64))
                        .map(|m| m.data)
                })
                .collect();
            if history.is_empty() {
                assert!(got.is_empty(), "{durability}: {got:?}");
            } else {
                assert_eq!(got, history, "{durability}");
            }
            topic.publish(10, Nanos::from_millis(110), None);
            assert_eq!(
                topic.read(Nanos::from_millis(111)).map(|m| m.data),
                Some(10)
            );
            let s = topic.stats();
            assert_eq!(
                s.history_on_join,
                Some(history.len() as u64),
                "{durability}"
            );
            assert_eq!(s.before_join, 10 - history.len() as u64, "{durability}");
            assert_eq!(s.unmatched, 0, "a late joiner is no incompatible pair");
            assert_eq!(
                s.dropped, 0,
                "what fell out of the history was never delivered"
            );
            assert_eq!(
                s.published,
                s.seen + s.dropped + s.before_join + topic.unseen_buffered() as u64,
                "{durability}: {s:?}"
            );
        }
        // Over a link, a message published before the join and landing after it is still
        // one from before: a volatile topic never delivers it.
        let topic = q(3, "delay_ms=30");
        topic.set_joins_at(Nanos::from_millis(100));
        topic.publish(1, Nanos::from_millis(90), None);
        assert_eq!(topic.read(Nanos::from_millis(130)), None);
        topic.publish(2, Nanos::from_millis(110), None);
        assert_eq!(topic.read(Nanos::from_millis(140)).map(|m| m.data), Some(2));
        let s = topic.stats();
        assert_eq!((s.before_join, s.history_on_join), (1, Some(0)), "{s:?}");
        // A publisher that joins late owes no deadline before it exists.
        let topic = q(1, "deadline_ms=20");
        topic.set_publisher_start(Nanos::from_millis(1000));
        topic.publish(1, Nanos::from_millis(1000), None);
        assert_eq!(
            topic
                .stats_at(Nanos::from_millis(1010))
                .offered_deadline_missed,
            0
        );
    }
}
