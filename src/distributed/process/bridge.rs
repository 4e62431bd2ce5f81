//! The topics that cross a process's boundary, its bridge to the others: which topics cross
//! ([`crossings`]), the sending end of each outbound one (an [`Outlet`], each message put
//! on the wire as it is published, within the publishing tick, or kept until its tick's
//! reports go; samples a lockstep advance
//! holds back, or keeps to carry its reports, [`Spill`]), and the receiving end of each inbound one (its subscription, the
//! arrivals the lockstep waits for, its over-the-wire latency, the samples refused).
//!
//! A large sample (an image, a scan) goes through the process's shared memory
//! ([`super::shm`]): written once, by its node into a buffer the topic lent or from the
//! message into the pool, and read in place on arrival (issue 76).

use super::shm::{read_arrived, SharedPool};
use super::*;
use crate::wire::SampleHead;
use zenoh::bytes::ZBytes;

/// One crossing topic's sending end in its publisher's process: the bridge element that
/// puts each message on the wire as it is published, from the topic's tap, under the topic's
/// lock and within the publishing tick (as ROS 2's `publish()` hands a message to its
/// middleware before it returns): a tick's measured time includes its sends. Under the
/// virtual clock between two processes linked directly a sample is kept until its tick's
/// reports go, which it carries ([`Spill::carrying`]).
pub(super) struct Outlet {
    pub(super) publisher: zenoh::pubsub::Publisher<'static>,
    /// The topic's index in the graph.
    pub(super) topic: usize,
    /// Where a sample goes when the tick runs on Zenoh's receive thread past its budget.
    pub(super) spill: Arc<Spill>,
    /// Where a large sample is written.
    pub(super) pool: Arc<SharedPool>,
    /// The newest seq sent since the publishing tick ended last ([`NOT_SENT`]: none).
    pub(super) newest: AtomicU64,
    /// Messages offered since the publishing tick ended last.
    pub(super) this_tick: AtomicU64,
    /// The topic's name, for the line that says a message was too large to send.
    pub(super) name: String,
    /// Whether that line was said (once per topic).
    pub(super) said_too_large: std::sync::atomic::AtomicBool,
}

/// What is said of a message of `len` bytes (encoded) too large to send.
pub(super) fn too_large(len: usize) -> String {
    ratelab_core::limits::refusal(
        format_args!(
            "a message of {len} bytes is larger than one may be between processes (at most {}: a sample's {} less its header): not sent, counted lost on the wire",
            ratelab_core::msg::MAX_PAYLOAD_BYTES,
            wire::MAX_SAMPLE_BYTES
        ),
        "MAX_SAMPLE_BYTES",
    )
}

/// [`Outlet::newest`] when nothing was sent.
pub(super) const NOT_SENT: u64 = u64::MAX;

impl Outlet {
    pub(super) fn new(
        publisher: zenoh::pubsub::Publisher<'static>,
        topic: usize,
        name: &str,
        (spill, pool): (Arc<Spill>, Arc<SharedPool>),
    ) -> Self {
        Outlet {
            publisher,
            topic,
            spill,
            pool,
            newest: AtomicU64::new(NOT_SENT),
            this_tick: AtomicU64::new(0),
            name: name.to_string(),
            said_too_large: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// Send one message (called from the topic's tap, as it is published). Past
    /// [`wire::MAX_SENT_PER_TICK`] in one tick the rest of that tick's are not sent (the
    /// subscriber counts them lost on the wire when a later one arrives). Nor is a message
    /// larger encoded than [`ratelab_core::msg::MAX_PAYLOAD_BYTES`], which every receiver refuses:
    /// it stays home, counted lost the same way (the lockstep does not wait for it), and the
    /// first one is said on stderr, naming the topic, its size and the bound.
    pub(super) fn send(
        &self,
        seq: u64,
        stamp: Nanos,
        origin: Option<Nanos>,
        data: &ratelab_core::msg::MsgData,
    ) {
        if self.this_tick.fetch_add(1, Ordering::Relaxed) >= wire::MAX_SENT_PER_TICK as u64 {
            return;
        }
        let head = SampleHead {
            seq,
            stamp_ns: stamp.0,
            origin_ns: origin.map(|o| o.0),
            sent_mono_ns: wire::mono_now_ns(),
        };
        let payload_len = data.encoded_len();
        if payload_len > ratelab_core::msg::MAX_PAYLOAD_BYTES {
            if !self.said_too_large.swap(true, Ordering::Relaxed) {
                eprintln!(
                    "[ratelab] {}: {}",
                    ratelab_core::text::printable(&self.name),
                    too_large(payload_len)
                );
            }
            return;
        }
        // Written once, straight from the message: into the shared pool when it is large
        // and the pool has room, else into bytes of its own.
        let Some((bytes, len)) = self.pool.written(&head, data, payload_len) else {
            return; // never: the length is the payload's (counted lost on the wire if it were)
        };
        if self.spill.admit(len) {
            // Under congestion control `Block` a put fails only when the session is closed,
            // which the run notices on its own.
            if let Some(bytes) = self.spill.admitted(self.topic, bytes) {
                let _ = self.publisher.put(bytes).wait();
            }
        } else {
            self.spill.hold(self.topic, bytes);
        }
        self.newest.store(seq, Ordering::Relaxed);
    }

    /// The publishing tick ended: the newest seq it sent, if any (for its report).
    pub(super) fn tick_ended(&self) -> Option<u64> {
        self.this_tick.store(0, Ordering::Relaxed);
        Some(self.newest.swap(NOT_SENT, Ordering::Relaxed)).filter(|&s| s != NOT_SENT)
    }
}

/// The samples held back from the wire by the current lockstep advance, and its budget;
/// and, when the reports ride on the samples ([`Spill::carrying`]), the samples kept to
/// carry them.
pub(super) struct Spill {
    /// Bytes the current advance may still put itself (`i64::MAX`: no bound).
    pub(super) left: std::sync::atomic::AtomicI64,
    /// Samples held back, in publish order: (topic index, encoded sample).
    pub(super) held: Mutex<std::collections::VecDeque<(usize, ZBytes)>>,
    /// The reports ride on the samples ([`Spill::carrying`]).
    carries: bool,
    /// Samples admitted to the wire and kept, in publish order, until the reports of the
    /// ticks that published them go: the last one put carries them ([`Bridge::put_kept`]).
    carried: Mutex<Vec<(usize, ZBytes)>>,
}

impl Spill {
    /// No bound: every sample is put as it is published (the real clock; the main thread).
    pub(super) fn unbounded() -> Arc<Spill> {
        Self::new(false)
    }

    /// As [`Spill::unbounded`], and the samples admitted are kept until the reports of
    /// their ticks go, which the last of them then carries ([`Bridge::put_kept`]): a
    /// launch of two processes linked directly under the virtual clock, where the one other
    /// process both reads every crossing sample and needs every report
    /// ([`crate::lockstep::reports_ride_on_samples`]). A hop then costs one message, where a
    /// sample and its report made two.
    pub(super) fn carrying() -> Arc<Spill> {
        Self::new(true)
    }

    fn new(carries: bool) -> Arc<Spill> {
        Arc::new(Spill {
            left: std::sync::atomic::AtomicI64::new(i64::MAX),
            held: Mutex::default(),
            carries,
            carried: Mutex::default(),
        })
    }

    /// From now on, the samples may put `budget` bytes themselves (`None`: no bound).
    pub(super) fn set_budget(&self, budget: Option<i64>) {
        self.left
            .store(budget.unwrap_or(i64::MAX), Ordering::SeqCst);
    }

    /// A sample of `len` bytes may go on the wire now: within the budget, and nothing held
    /// back before it (order is kept).
    pub(super) fn admit(&self, len: usize) -> bool {
        let len = i64::try_from(len).unwrap_or(i64::MAX);
        self.is_empty() && self.left.fetch_sub(len, Ordering::SeqCst) >= len
    }

    /// Hold `bytes`, a sample of topic `topic`, back from the wire, after any kept to carry
    /// reports (which are held back first: order is kept).
    pub(super) fn hold(&self, topic: usize, bytes: ZBytes) {
        let mut held = ratelab_runtime::graph::lock(&self.held);
        if self.carries {
            held.extend(ratelab_runtime::graph::lock(&self.carried).drain(..));
        }
        held.push_back((topic, bytes));
    }

    /// Send `bytes`, a sample of topic `topic` admitted to the wire ([`Spill::admit`]): kept
    /// to carry reports when the reports ride on the samples (`None` back), else given back
    /// to be put now.
    pub(super) fn admitted(&self, topic: usize, bytes: ZBytes) -> Option<ZBytes> {
        if !self.carries {
            return Some(bytes);
        }
        ratelab_runtime::graph::lock(&self.carried).push((topic, bytes));
        None
    }

    /// No sample is held back.
    pub(super) fn is_empty(&self) -> bool {
        ratelab_runtime::graph::lock(&self.held).is_empty()
    }
}

/// The crossing topics whose publisher runs here: each one's [`Outlet`], and the samples
/// held back from Zenoh's receive thread.
pub(super) struct Bridge {
    pub(super) outlets: Vec<Option<Outlet>>,
    /// Per node, the crossing topics it publishes.
    pub(super) by_node: Vec<Vec<TopicId>>,
    pub(super) spill: Arc<Spill>,
}

impl Bridge {
    /// After node `node`'s event: the (topic index, newest seq sent) of each crossing topic
    /// it sent on, for its report.
    pub(super) fn forward_after(&self, node: usize) -> Vec<(usize, u64)> {
        let Some(topics) = self.by_node.get(node) else {
            return Vec::new();
        };
        topics
            .iter()
            .filter_map(|t| Some((t.0, self.outlets[t.0].as_ref()?.tick_ended()?)))
            .collect()
    }

    /// Put the samples kept to carry reports ([`Spill::carrying`]), in order, the last with
    /// `reports` (an encoded message of tick reports, [`wire::encode_reports`]), if any, as
    /// its attachment. Returns the reports when no sample was kept to carry them, for them to
    /// go on their own key.
    ///
    /// # Errors
    /// When the session is closed.
    pub(super) fn put_kept(&self, reports: Option<Vec<u8>>) -> zenoh::Result<Option<Vec<u8>>> {
        if !self.spill.carries {
            return Ok(reports);
        }
        let kept = std::mem::take(&mut *ratelab_runtime::graph::lock(&self.spill.carried));
        let last = kept.len().checked_sub(1);
        let mut reports = reports;
        for (k, (t, bytes)) in kept.into_iter().enumerate() {
            let Some(o) = self.outlets.get(t).and_then(Option::as_ref) else {
                continue;
            };
            let put = o.publisher.put(bytes);
            match Some(k) == last {
                true => put.attachment(reports.take()).wait()?,
                false => put.wait()?,
            }
        }
        Ok(reports)
    }

    /// Put the samples held back on the wire, oldest first (from the main thread).
    ///
    /// # Errors
    /// When the session is closed.
    pub(super) fn put_held(&self) -> zenoh::Result<()> {
        loop {
            let Some((t, bytes)) = ratelab_runtime::graph::lock(&self.spill.held).pop_front()
            else {
                return Ok(());
            };
            if let Some(o) = self.outlets.get(t).and_then(Option::as_ref) {
                o.publisher.put(bytes).wait()?;
            }
        }
    }
}

/// In `seqs` (the newest seq received per topic), topic `t` has received `seq` or anything
/// after it.
pub(super) fn arrived(seqs: &[Option<u64>], t: TopicId, seq: u64) -> bool {
    seqs.get(t.0).copied().flatten().is_some_and(|s| s >= seq)
}

/// The sequence numbers that have arrived per inbound topic, for the lockstep's waits.
pub(super) struct Arrivals {
    pub(super) seqs: Mutex<Vec<Option<u64>>>,
    pub(super) cv: Condvar,
}

impl Arrivals {
    /// Topic `t` has received `seq` (or anything after it).
    pub(super) fn has(&self, t: TopicId, seq: u64) -> bool {
        arrived(&ratelab_runtime::graph::lock(&self.seqs), t, seq)
    }

    /// Wait until topic `t` has received `seq` (or anything after it), until `deadline`
    /// or `stop`: whether it has.
    pub(super) fn wait_for(
        &self,
        t: TopicId,
        seq: u64,
        deadline: Instant,
        stop: &StopFlag,
    ) -> bool {
        let mut seqs = ratelab_runtime::graph::lock(&self.seqs);
        loop {
            if arrived(&seqs, t, seq) {
                return true;
            }
            let now = Instant::now();
            if now >= deadline || stop.is_stopped() {
                return false;
            }
            let wait = (deadline - now).min(Duration::from_millis(100));
            seqs = self
                .cv
                .wait_timeout(seqs, wait)
                .map(|(g, _)| g)
                .unwrap_or_else(|e| e.into_inner().0);
        }
    }
}

/// The Zenoh publishers of a process's outbound topics.
pub(super) type Publishers = Vec<(TopicId, zenoh::pubsub::Publisher<'static>)>;

/// Wire the topics crossing this process's boundary (`mine`, the nodes of `process`):
/// the publisher's side of each outbound topic becomes a plain buffer (the subscriber's
/// copy keeps the QoS) and gets a Zenoh publisher that never drops (a lost sample would
/// stall the run), on the key through which the launcher passes its samples on
/// ([`Keys::via`]), or, in a launch linked directly (`direct`), on the topic's own key,
/// which the subscribing processes hear over their own links; each inbound topic is
/// subscribed to, on its key. Returns the inbound topics, their subscriptions and the
/// outbound publishers. Linked directly under the real clock (`real`), a publisher drops
/// what a full link cannot take (counted lost on the wire by the subscriber), as the
/// launcher's outbox does in a star, so that a frozen subscriber never holds up the
/// publishing tick. Under the virtual clock each arrival advances the lockstep in `slot`,
/// and with `carry` the reports a sample carries are taken in
/// ([`crate::lockstep::reports_ride_on_samples`]).
pub(super) fn wire_crossings(
    (session, direct, real): (&zenoh::Session, bool, bool),
    keys: &Keys,
    handles: &ratelab_runtime::graph::GraphHandles,
    (mine, process): (&[NodeId], &str),
    (slot, carry): (Option<stepper::SharedSlot>, bool),
) -> Result<(Vec<TopicId>, Inbound, Publishers), DistError> {
    let spec = &handles.spec;
    let (inbound, outbound) = crossings(spec, mine);
    for &t in &outbound {
        let _ = handles.topic(t).set_depth(1);
        handles.topic(t).set_qos(TopicQos::default());
        // A buffer for the wire, not a subscription: whatever the subscriber requested is
        // judged in its own process, on its own copy.
        handles.topic(t).set_matched(true);
    }
    let into = (&inbound[..], slot, carry);
    let ends = subscribe_inbound(session, keys, spec, handles, into, process)?;
    let congestion = match direct && real {
        true => zenoh::qos::CongestionControl::Drop,
        false => zenoh::qos::CongestionControl::Block,
    };
    let publishers = outbound
        .iter()
        .map(|&t| {
            let name = &spec.topic(t).name;
            let key = if direct {
                keys.topic(name)
            } else {
                keys.via(name)
            };
            let publisher = session
                .declare_publisher(key)
                .congestion_control(congestion);
            Ok((t, publisher.wait()?))
        })
        .collect::<Result<_, DistError>>()?;
    Ok((inbound, ends, publishers))
}

/// Which of `spec`'s topics cross this process's boundary, for the process running nodes
/// `mine`: (inbound: another process publishes, one of `mine` reads; outbound: one of
/// `mine` publishes, another process reads), each in the graph's topic order. The one
/// place this is decided: the subscriptions, the bridges, the waits and the wire figures
/// all follow it.
pub(super) fn crossings(spec: &GraphSpec, mine: &[NodeId]) -> (Vec<TopicId>, Vec<TopicId>) {
    let owns = |id: NodeId| mine.contains(&id);
    let topics = || (0..spec.topics.len()).map(TopicId);
    let inbound = topics()
        .filter(|&t| {
            let ts = spec.topic(t);
            ts.subscriber().is_some_and(owns) && !owns(ts.publisher)
        })
        .collect();
    let outbound = topics()
        .filter(|&t| {
            let ts = spec.topic(t);
            owns(ts.publisher) && ts.subscriber().is_some_and(|s| !owns(s))
        })
        .collect();
    (inbound, outbound)
}

/// Subscribe to each `inbound` topic's key: each sample is decoded exactly and delivered
/// into the topic's copy here (or refused and counted, [`Refusals`]), its seq noted in the
/// returned [`Arrivals`] and its time on the wire in the returned per-topic latencies.
/// Under the virtual clock each arrival then advances the lockstep in `slot`, on Zenoh's
/// receive thread ([`stepper`]); with `carry`, after taking in the reports the sample
/// carries ([`crate::lockstep::reports_ride_on_samples`]).
///
/// # Errors
/// [`DistError::Zenoh`] when a subscriber cannot be declared.
pub(super) fn subscribe_inbound(
    session: &zenoh::Session,
    keys: &Keys,
    spec: &GraphSpec,
    handles: &ratelab_runtime::graph::GraphHandles,
    (inbound, slot, carry): (&[TopicId], Option<stepper::SharedSlot>, bool),
    process: &str,
) -> Result<Inbound, DistError> {
    let arrivals = Arc::new(Arrivals {
        seqs: Mutex::new(vec![None; spec.topics.len()]),
        cv: Condvar::new(),
    });
    // One histogram per inbound topic only (about 270 KB each: one per topic of a
    // 1,000-topic graph held 280 MB in every process).
    let wire_latency: Arc<Vec<Mutex<Received>>> = Arc::new(
        inbound
            .iter()
            .map(|_| Mutex::new(Received::default()))
            .collect(),
    );
    let mut subscribers = Vec::new();
    let refusals = Arc::new(Refusals::default());
    for (i, &t) in inbound.iter().enumerate() {
        let topic = handles.topic(t).clone();
        let arrivals = arrivals.clone();
        let lat = wire_latency.clone();
        let offset = Mutex::new(None);
        let refusals = refusals.clone();
        let process = process.to_string();
        let slot = slot.clone();
        let publisher = spec.process_of(spec.topic(t).publisher);
        subscribers.push(
            session
                .declare_subscriber(keys.topic(&spec.topic(t).name))
                .callback(move |s| {
                    // The reports the sample carries, if any (two processes linked
                    // directly, `lockstep::reports_ride_on_samples`): taken in whatever
                    // becomes of the sample, as the run cannot go on without them.
                    let attached = s.attachment().filter(|_| carry);
                    let carried =
                        (slot.as_ref()).zip(attached).map(
                            |(slot, a)| match lockstep::decode_carried(&a.to_bytes(), &publisher) {
                                Some(ms) => slot.take_in(ms),
                                None => {
                                    let why = "reports that are not its publisher's";
                                    refusals.note(&process, topic.name(), why);
                                    false
                                }
                            },
                        );
                    // Read in place: from the shared buffer itself when it came through
                    // shared memory (its pixels then a view of it), else from Zenoh's bytes.
                    let read = read_arrived(s.payload(), |sample, shared| -> Result<_, String> {
                        let sample = sample?;
                        let offset = &mut ratelab_runtime::graph::lock(&offset);
                        sample.deliver(&topic, offset, shared)?;
                        let pieces = matches!(sample.data, wire::Payload::Pieces { .. });
                        let (in_place, drawn) = (shared.is_some(), shared.is_some() && pieces);
                        Ok((sample.head.seq, sample.head.sent_mono_ns, in_place, drawn))
                    });
                    let (seq, sent, in_place, drawn) = match read {
                        Ok(read) => read,
                        Err(e) => {
                            refusals.note(&process, topic.name(), &e);
                            if let (Some(slot), Some(true)) = (&slot, carried) {
                                slot.wake(false);
                            }
                            return;
                        }
                    };
                    let took = wire::mono_now_ns().saturating_sub(sent);
                    let mut got = ratelab_runtime::graph::lock(&lat[i]);
                    got.latency.record(Nanos(took));
                    got.in_place += u64::from(in_place);
                    got.drawn_in_place += u64::from(drawn);
                    drop(got);
                    {
                        let mut seqs = ratelab_runtime::graph::lock(&arrivals.seqs);
                        seqs[t.0] = Some(seq);
                        arrivals.cv.notify_all();
                    }
                    if let Some(slot) = &slot {
                        slot.wake(false);
                    }
                })
                .wait()?,
        );
    }
    Ok(Inbound {
        subscribers,
        arrivals,
        wire_latency,
    })
}

/// This process's inbound topics as [`subscribe_inbound`] set them up.
pub(super) struct Inbound {
    /// One per inbound topic, kept for the run.
    pub(super) subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    /// The newest seq received on each topic.
    pub(super) arrivals: Arc<Arrivals>,
    /// Per inbound topic (in the order given), the over-the-wire latency of what arrived.
    pub(super) wire_latency: Arc<Vec<Mutex<Received>>>,
}

/// Make each crossing topic whose publisher runs here a bridge element (`publishers`: the
/// topic and its key's publisher): its tap sends each message as it is published. Called
/// before the process says it is ready: the shared-memory pool of a topic whose messages
/// may be large is made here ([`SharedPool::make_now`]). With `carry`, the samples are kept
/// to carry their ticks' reports ([`Spill::carrying`]). Returns
/// the bridge, which says after a local node's event what it published across the
/// boundary and the newest seq sent on each.
pub(super) fn bridge_outbound(
    spec: &GraphSpec,
    handles: &ratelab_runtime::graph::GraphHandles,
    publishers: Vec<(TopicId, zenoh::pubsub::Publisher<'static>)>,
    carry: bool,
) -> Arc<Bridge> {
    let spill = match carry {
        true => Spill::carrying(),
        false => Spill::unbounded(),
    };
    let pool = SharedPool::new(crate::shared_memory().unwrap_or(false));
    // A message with a field of bytes (an image's pixels) may be large: its pool is made
    // now, before the run, not at its first frame. No other process pays for a pool it may
    // never use (Zenoh locks it in memory).
    let may_be_large = |t: TopicId| {
        (spec.topic(t).msg.fields().iter()).any(|f| f.kind == ratelab_core::msg::FieldKind::Bytes)
    };
    if publishers.iter().any(|(t, _)| may_be_large(*t)) {
        pool.make_now();
    }
    let mut outlets: Vec<Option<Outlet>> = (0..spec.topics.len()).map(|_| None).collect();
    for (t, p) in publishers {
        let name = &spec.topic(t).name;
        outlets[t.0] = Some(Outlet::new(p, t.0, name, (spill.clone(), pool.clone())));
    }
    // Per node, the crossing topics it publishes.
    let by_node: Vec<Vec<TopicId>> = (0..spec.nodes.len())
        .map(|i| {
            let publishes = &spec.node(NodeId(i)).publishes;
            publishes
                .iter()
                .copied()
                .filter(|t| outlets[t.0].is_some())
                .collect()
        })
        .collect();
    let bridge = Arc::new(Bridge {
        outlets,
        by_node,
        spill,
    });
    // A crossing topic is a bridge element of the graph: its tap sends each message as it
    // is published (held outputs when they go out), in order, so a node that publishes
    // twice in a tick sends both, as in one process. The publishing tick's report then
    // names the newest seq sent, which a process reading the topic under the virtual clock
    // waits for.
    //
    // A topic whose frames may be large lends its publisher buffers of the pool to draw
    // them into ([`ratelab_core::msg::AnyTopic::loan_pixels`]): a frame drawn there crosses
    // without a copy.
    for t in (0..bridge.outlets.len()).filter(|&t| bridge.outlets[t].is_some()) {
        if may_be_large(TopicId(t)) && pool.enabled() {
            handles.topic(TopicId(t)).set_lender(pool.clone());
        }
        let bridge = bridge.clone();
        handles
            .topic(TopicId(t))
            .add_data_tap(Box::new(move |seq, stamp, origin, data| {
                if let Some(o) = &bridge.outlets[t] {
                    o.send(seq, stamp, origin, &data);
                }
            }));
    }
    bridge
}

/// What one inbound topic received, for its [`wire::WireLink`].
#[derive(Default)]
pub(super) struct Received {
    /// Each sample's time on the wire.
    pub(super) latency: LatencyStats,
    /// Samples that arrived in shared memory and were read there, in place
    /// ([`read_arrived`]).
    pub(super) in_place: u64,
    /// Of those, the samples whose frame was the buffer its publisher's node drew into
    /// (they arrived in pieces, [`wire::Payload::Pieces`]).
    pub(super) drawn_in_place: u64,
}

/// The over-the-wire latency of each inbound topic so far (µs, to 0.1); `lat` holds one
/// per inbound topic, in `inbound`'s order ([`subscribe_inbound`]).
pub(super) fn wire_links(
    process: &str,
    spec: &GraphSpec,
    inbound: &[TopicId],
    lat: &[Mutex<Received>],
) -> Vec<wire::WireLink> {
    inbound
        .iter()
        .zip(lat)
        .map(|(&t, l)| {
            let got = ratelab_runtime::graph::lock(l);
            let l = &got.latency;
            let us = |n: Option<Nanos>| {
                n.map_or(0.0, |n| {
                    ratelab_core::metrics::round_to(n.as_micros_f64(), 1)
                })
            };
            wire::WireLink {
                topic: spec.topic(t).name.clone(),
                process: process.to_string(),
                samples: l.count(),
                p50_us: us(l.quantile(0.5)),
                p99_us: us(l.quantile(0.99)),
                max_us: us(l.max()),
                in_place: got.in_place,
                drawn_in_place: got.drawn_in_place,
                since_ns: None,
            }
        })
        .collect()
}

/// Samples a process refused (malformed, of the wrong type, numbered out of bounds): counted,
/// and said on stderr (which the launcher shows) at the first and then at most every 10 s,
/// so a flood of bad samples cannot flood the terminal. The line holds only what this
/// process wrote (the topic's name from its own graph, the reason), never the sample's text.
#[derive(Default)]
pub(super) struct Refusals {
    pub(super) count: AtomicU64,
    /// When the last line was printed, CLOCK_MONOTONIC ns (0: never).
    pub(super) said_at: AtomicU64,
}

impl Refusals {
    /// Period between two lines, ns.
    const EVERY_NS: u64 = 10_000_000_000;

    pub(super) fn note(&self, process: &str, topic: &str, reason: &str) {
        let n = self.count.fetch_add(1, Ordering::SeqCst) + 1;
        let now = wire::mono_now_ns().max(1);
        let last = self.said_at.load(Ordering::SeqCst);
        if (last == 0 || now.saturating_sub(last) >= Self::EVERY_NS)
            && self
                .said_at
                .compare_exchange(last, now, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
        {
            eprintln!("[ratelab] {process}: {topic}: refused {reason} ({n} refused so far)");
        }
    }
}
