//! The topics that cross a process's boundary, its bridge to the others: which topics cross
//! ([`crossings`]), the sending end of each outbound one (an [`Outlet`], each message put
//! on the wire as it is published, within the publishing tick; samples a lockstep advance
//! holds back, [`Spill`]), and the receiving end of each inbound one (its subscription, the
//! arrivals the lockstep waits for, its over-the-wire latency, the samples refused).
//!
//! A large sample (an image, a scan: [`SHM_THRESHOLD_BYTES`] or more) is written once,
//! straight from the message into a buffer of the process's shared-memory pool
//! ([`SharedPool`]), and read in place on arrival: its pixels stay a view of the shared
//! buffer ([`shared_payload`]) unless the node must own a copy (issue 76).

use super::*;
use crate::wire::{SampleHead, SampleView};
use crate::{SHM_POOL_BYTES, SHM_THRESHOLD_BYTES};
use ratelab_core::msg::MsgData;
use zenoh::bytes::ZBytes;
use zenoh::shm::{
    Defragment, GarbageCollect, PosixShmProviderBackend, ShmProvider, ShmProviderBuilder, ZShmMut,
};

/// A process's shared-memory pool for its large samples: its own ([`SHM_POOL_BYTES`], made
/// as the process starts when it publishes a topic whose message type has a field of bytes,
/// else in the background when the first large sample is sent; Zenoh's copying of large payloads
/// into a pool of its own is off, [`crate::open_session`]). A buffer returns to it only when
/// no process holds it any more (Zenoh's safe garbage collection): a subscriber keeps a
/// frame's buffer as long as it keeps the message, as its pixels ([`shared_payload`]), and
/// the bytes must not change under it.
pub(super) struct SharedPool {
    /// Shared memory is on ([`crate::shared_memory`]).
    enabled: bool,
    /// The pool once made (`Some(None)`: it could not be made; large samples cross the
    /// socket).
    provider: Arc<std::sync::OnceLock<Option<ShmProvider<PosixShmProviderBackend>>>>,
    /// Whether the pool is being made.
    started: std::sync::atomic::AtomicBool,
}

impl SharedPool {
    /// A pool, when `enabled` (shared memory on), made when first needed.
    pub(super) fn new(enabled: bool) -> Arc<SharedPool> {
        Arc::new(SharedPool {
            enabled,
            provider: Arc::default(),
            started: std::sync::atomic::AtomicBool::new(false),
        })
    }

    /// Make the pool now, on this thread (once, when shared memory is on): a process whose
    /// outbound topics carry a field of bytes (an image) does so as it starts, before it says it is
    /// ready ([`bridge_outbound`]), so that its first frame goes through shared memory
    /// however long mapping [`SHM_POOL_BYTES`] takes on a loaded machine.
    pub(super) fn make_now(&self) {
        if self.enabled && !self.started.swap(true, Ordering::SeqCst) {
            let _ = self.provider.set(Self::provider());
        }
    }

    /// Start making the pool (once, when shared memory is on) off the caller's thread: a
    /// tick's, which must not wait for the mapping.
    fn make(&self) {
        if !self.enabled || self.started.swap(true, Ordering::SeqCst) {
            return;
        }
        let cell = self.provider.clone();
        let made = std::thread::Builder::new()
            .name("ratelab-shm-pool".into())
            .spawn(move || {
                let _ = cell.set(Self::provider());
            });
        if made.is_err() {
            let _ = self.provider.set(None);
        }
    }

    /// A new pool of [`SHM_POOL_BYTES`], or `None` (said once) when it cannot be made:
    /// large samples then cross the socket.
    fn provider() -> Option<ShmProvider<PosixShmProviderBackend>> {
        let made = ShmProviderBuilder::default_backend(SHM_POOL_BYTES).wait();
        if let Err(e) = &made {
            eprintln!("[ratelab] no shared-memory pool ({e}): large samples cross the socket");
        }
        made.ok()
    }

    /// A buffer of `len` bytes in the pool, if it has room now: `None` when the sample is
    /// small (under [`SHM_THRESHOLD_BYTES`], it crosses the socket), when shared memory is
    /// off or the pool is still being made (the first large samples), or when the pool is
    /// full even after reclaiming what every receiver has let go (never blocks: a tick must
    /// not wait on a subscriber whose queue holds the pool's buffers; the sample then
    /// crosses the socket).
    fn buffer(&self, len: usize) -> Option<ZShmMut> {
        if len < SHM_THRESHOLD_BYTES || !self.enabled {
            return None;
        }
        let Some(provider) = self.provider.get() else {
            self.make();
            return None;
        };
        // Safe policies only: a buffer a receiver still holds is never reclaimed.
        provider
            .as_ref()?
            .alloc(len)
            .with_policy::<Defragment<GarbageCollect>>()
            .wait()
            .ok()
    }

    /// The sample of `head` and `data` (its payload `payload_len` bytes,
    /// [`MsgData::encoded_len`]), written once: into a buffer of the pool when
    /// [`SharedPool::buffer`] gives one, else into bytes of its own; with its length.
    /// `None` only if `payload_len` is not the payload's length.
    fn written(
        &self,
        head: &SampleHead,
        data: &MsgData,
        payload_len: usize,
    ) -> Option<(ZBytes, usize)> {
        let len = head.sample_len(payload_len);
        if let Some(mut shared) = self.buffer(len) {
            let written = head.write(data, payload_len, &mut shared);
            return written.ok().map(|()| (shared.into(), len));
        }
        let mut own = vec![0; len];
        let written = head.write(data, payload_len, &mut own);
        written.ok().map(|()| (own.into(), len))
    }
}

/// A sample that arrived in shared memory as bytes that keep its buffer mapped, so that the
/// message's pixels can be a view of it ([`SampleView::deliver`]); `None` for any other
/// sample (through the socket, in a receive batch Zenoh reuses: its pixels are copied).
/// Only a launch's processes may put on a topic's key (its access control), and each writes
/// into a [`SharedPool`], whose buffers are never reclaimed while held: a view stays valid.
pub(super) fn shared_payload(payload: &ZBytes) -> Option<bytes::Bytes> {
    payload.as_shm()?;
    let mut slices = payload.slices();
    match (slices.next(), slices.next()) {
        (Some(_), None) => Some(bytes::Bytes::from_owner(OneSlice(payload.clone()))),
        _ => None,
    }
}

/// A payload of one run of bytes, as [`bytes::Bytes::from_owner`] takes it.
struct OneSlice(ZBytes);

impl AsRef<[u8]> for OneSlice {
    fn as_ref(&self) -> &[u8] {
        self.0.slices().next().unwrap_or_default()
    }
}

/// One crossing topic's sending end in its publisher's process: the bridge element that
/// puts each message on the wire as it is published, from the topic's tap, under the topic's
/// lock and within the publishing tick (as ROS 2's `publish()` hands a message to its
/// middleware before it returns): a tick's measured time includes its sends.
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
            let _ = self.publisher.put(bytes).wait();
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

/// The samples held back from the wire by the current lockstep advance, and its budget.
pub(super) struct Spill {
    /// Bytes the current advance may still put itself (`i64::MAX`: no bound).
    pub(super) left: std::sync::atomic::AtomicI64,
    /// Samples held back, in publish order: (topic index, encoded sample).
    pub(super) held: Mutex<std::collections::VecDeque<(usize, ZBytes)>>,
}

impl Spill {
    /// No bound: every sample is put as it is published (the real clock; the main thread).
    pub(super) fn unbounded() -> Arc<Spill> {
        Arc::new(Spill {
            left: std::sync::atomic::AtomicI64::new(i64::MAX),
            held: Mutex::default(),
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

    pub(super) fn hold(&self, topic: usize, bytes: ZBytes) {
        ratelab_runtime::graph::lock(&self.held).push_back((topic, bytes));
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
/// ([`Keys::via`]); each inbound topic is subscribed to, on its key. Returns the inbound
/// topics, their subscriptions and the outbound publishers.
pub(super) fn wire_crossings(
    session: &zenoh::Session,
    keys: &Keys,
    handles: &ratelab_runtime::graph::GraphHandles,
    (mine, process): (&[NodeId], &str),
    slot: Option<stepper::SharedSlot>,
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
    let ends = subscribe_inbound(session, keys, spec, handles, (&inbound, slot), process)?;
    let block = zenoh::qos::CongestionControl::Block;
    let publishers = outbound
        .iter()
        .map(|&t| {
            let key = keys.via(&spec.topic(t).name);
            let publisher = session.declare_publisher(key).congestion_control(block);
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
/// receive thread ([`stepper`]).
///
/// # Errors
/// [`DistError::Zenoh`] when a subscriber cannot be declared.
pub(super) fn subscribe_inbound(
    session: &zenoh::Session,
    keys: &Keys,
    spec: &GraphSpec,
    handles: &ratelab_runtime::graph::GraphHandles,
    (inbound, slot): (&[TopicId], Option<stepper::SharedSlot>),
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
        subscribers.push(
            session
                .declare_subscriber(keys.topic(&spec.topic(t).name))
                .callback(move |s| {
                    // Read in place: from the shared buffer itself when it came through
                    // shared memory (its pixels then a view of it), else from Zenoh's bytes.
                    let shared = shared_payload(s.payload());
                    let copied;
                    let bytes: &[u8] = match &shared {
                        Some(shared) => shared,
                        None => {
                            copied = s.payload().to_bytes();
                            &copied
                        }
                    };
                    let sample = match SampleView::decode(bytes) {
                        Ok(sample) => sample,
                        Err(e) => return refusals.note(&process, topic.name(), &e),
                    };
                    let (seq, sent) = (sample.head.seq, sample.head.sent_mono_ns);
                    let offset = &mut ratelab_runtime::graph::lock(&offset);
                    if let Err(e) = sample.deliver(&topic, offset, shared.as_ref()) {
                        return refusals.note(&process, topic.name(), &e);
                    }
                    let took = wire::mono_now_ns().saturating_sub(sent);
                    let mut got = ratelab_runtime::graph::lock(&lat[i]);
                    got.latency.record(Nanos(took));
                    got.in_place += u64::from(shared.is_some());
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
/// may be large is made here ([`SharedPool::make_now`]). Returns
/// the bridge, which says after a local node's event what it published across the
/// boundary and the newest seq sent on each.
pub(super) fn bridge_outbound(
    spec: &GraphSpec,
    handles: &ratelab_runtime::graph::GraphHandles,
    publishers: Vec<(TopicId, zenoh::pubsub::Publisher<'static>)>,
) -> Arc<Bridge> {
    let spill = Spill::unbounded();
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
    for t in (0..bridge.outlets.len()).filter(|&t| bridge.outlets[t].is_some()) {
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
    /// ([`shared_payload`]).
    pub(super) in_place: u64,
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

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::msg::{AnyTopic, ImageMsg, Message};

    /// A plain Zenoh session on this host (no TLS), with shared memory as ratelab's.
    fn session(listen: &[String], connect: &[String]) -> zenoh::Session {
        let mut config = zenoh::Config::default();
        let json = |v: &[String]| serde_json::to_string(v).unwrap();
        for (key, value) in [
            ("listen/endpoints", json(listen)),
            ("connect/endpoints", json(connect)),
            ("scouting/multicast/enabled", "false".into()),
            ("transport/shared_memory/enabled", "true".into()),
            // As ratelab's sessions: only what a process writes into its pool goes through
            // shared memory, never Zenoh's own copy.
            (
                "transport/shared_memory/transport_optimization/enabled",
                "false".into(),
            ),
        ] {
            config.insert_json5(key, &value).expect("a Zenoh setting");
        }
        zenoh::open(config).wait().expect("a session")
    }

    /// A camera's frame crosses from one session to another without a copy of its pixels on
    /// arrival: the receiver's message holds a view of the shared buffer the sender wrote the
    /// sample into, once, straight from the message. A small message still crosses the
    /// socket.
    #[test]
    fn a_large_message_is_written_into_shared_memory_once_and_read_in_place() {
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let far = session(std::slice::from_ref(&endpoint), &[]);
        let near = session(&[], std::slice::from_ref(&endpoint));
        let topic = AnyTopic::new("/image", ImageMsg::TYPE, 4).unwrap();
        let (tx, rx) = crossbeam_channel::unbounded();
        let t = topic.clone();
        let offset = Mutex::new(None);
        let _sub = far
            .declare_subscriber("t/image")
            .callback(move |s| {
                let shared = shared_payload(s.payload());
                let bytes = s.payload().to_bytes().into_owned();
                let read = match &shared {
                    Some(b) => SampleView::decode(b),
                    None => SampleView::decode(&bytes),
                };
                let view = read.expect("a sample");
                let offset = &mut ratelab_runtime::graph::lock(&offset);
                view.deliver(&t, offset, shared.as_ref())
                    .expect("delivered");
                let data = t.read(Nanos(u64::MAX / 2)).expect("published").data;
                let _ = tx.send((view.head.seq, shared, data));
            })
            .wait()
            .expect("a subscriber");
        let publisher = near.declare_publisher("t/image").wait().unwrap();
        let deadline = Instant::now() + Duration::from_secs(20);
        while !publisher
            .matching_status()
            .wait()
            .is_ok_and(|m| m.matching())
        {
            assert!(Instant::now() < deadline, "the subscriber was never seen");
            std::thread::sleep(Duration::from_millis(10));
        }
        let pool = SharedPool::new(true);
        let frame = |seq: u64| {
            let pixels: Vec<u8> = (0..640 * 480u32).map(|i| (i as u64 + seq) as u8).collect();
            MsgData::new(ImageMsg {
                height: 480,
                width: 640,
                encoding: "mono8".into(),
                step: 640,
                data: pixels.into(),
            })
        };
        // The pool is made when first asked, in the background: until it is ready the
        // frames cross the socket (and still arrive).
        let mut seq = 0;
        let (sent, got) = loop {
            assert!(Instant::now() < deadline, "the pool was never ready");
            let data = frame(seq);
            let head = SampleHead {
                seq,
                stamp_ns: seq,
                origin_ns: None,
                sent_mono_ns: wire::mono_now_ns(),
            };
            let (bytes, _) = pool
                .written(&head, &data, data.encoded_len())
                .expect("written");
            let in_pool = bytes.as_shm().is_some();
            publisher.put(bytes).wait().unwrap();
            let got = rx.recv_timeout(Duration::from_secs(10)).expect("arrived");
            assert_eq!(got.0, seq);
            assert_eq!(got.2, data, "the frame, whole");
            if in_pool {
                break (data, got);
            }
            seq += 1;
            std::thread::sleep(Duration::from_millis(50));
        };
        let (_, shared, data) = got;
        let shared = shared.expect("the frame arrived in shared memory");
        let img = data.get::<ImageMsg>().unwrap();
        assert!(
            img.data.is_within(&shared),
            "the pixels are a view of the shared buffer"
        );
        assert!(!img.data.shares(&sent.get::<ImageMsg>().unwrap().data));
        // A small message (a force) is not put in the pool: it crosses the socket.
        let force = MsgData::new(ratelab_core::msg::ForceMsg { newtons: 1.0 });
        let head = SampleHead {
            seq: 0,
            stamp_ns: 0,
            origin_ns: None,
            sent_mono_ns: 0,
        };
        let (small, _) = pool.written(&head, &force, force.encoded_len()).unwrap();
        assert!(small.as_shm().is_none());
        // With shared memory off, nothing is put in a pool.
        let big = frame(0);
        let off = SharedPool::new(false);
        assert!(off.buffer(head.sample_len(big.encoded_len())).is_none());
        let (own, len) = off.written(&head, &big, big.encoded_len()).unwrap();
        assert!(own.as_shm().is_none());
        assert_eq!(len, head.sample_len(big.encoded_len()));
        // A payload length that is not the payload's writes nothing.
        assert!(off.written(&head, &big, big.encoded_len() + 1).is_none());
    }
}
