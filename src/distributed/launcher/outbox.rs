//! What the launcher passes on to the processes of a star from Zenoh's thread (the crossing
//! topics' samples and the lockstep's relayed reports): sent from a thread of its own, or,
//! for a small message with nothing queued ahead of it, put there and then. (In a launch
//! linked directly the processes send both to each other and nothing passes here but the
//! reports handed on at the end.)
//!
//! The launcher's session is the router of the launch's star, and Zenoh runs it on one
//! thread ([`crate::ZENOH_RUNTIME`]): the thread that receives a message is the one that
//! writes what is queued for every link. A message put on that thread into a link whose
//! queue is full waits for room that only that thread can make, for Zenoh's 5 s, and then
//! Zenoh closes the link. Routed by Zenoh itself, a sample larger than a link's queue (a
//! camera frame without shared memory: 300 KiB at 640×480) would do just that. So a
//! process puts each sample of a crossing topic on `ratelab/<graph>/@via/<topic>`
//! ([`crate::Keys::via`]), which only the launcher hears ([`forward_topics`]); its callback
//! hands the sample to this outbox, and the outbox's thread puts it on the topic's key,
//! waiting for room as long as it takes while Zenoh's thread writes. The relayed reports
//! go the same way ([`super::relay`]), in the order they were handed in: a sample a
//! report names reaches its subscriber before the report does.
//!
//! With shared memory the sample stays a reference to the publisher's segment all the way.
//!
//! A small message ([`MAX_DIRECT_BYTES`] on the wire: a sample in shared memory is a
//! reference to its buffer there, [`wire_bytes`]) is put straight from the thread that hands
//! it in (Zenoh's, or the launcher's main thread at the run's end) when nothing waits in its
//! process's outbox and the process has been handed under [`MAX_DIRECT_UNANSWERED_BYTES`] in
//! all (put directly or queued) since the launcher last heard from it
//! ([`Outbox::answered`]: under the virtual clock each of its reports, in every turn it
//! takes; under the real clock its live figures, every [`crate::process::STATS_PERIOD`]).
//! The hand-off to the outbox's thread cost an instant of the chapter's launch about a third
//! of its time, and a frame in shared memory the same hop again (BENCHMARKS.md, issue 76
//! items 1 and 4). A link's queue at the router (16 batches of 64 KiB a priority,
//! [`crate::open_router`]) does not fill with so few bytes to a process that keeps reading.
//! Past the bound, or with anything queued (whose order a message must keep), the message
//! takes the outbox: a process that stopped (frozen, gone) is soon handed everything there,
//! where under the real clock its samples are dropped once its outbox is full.
//!
//! What the bound does not cover, and what then happens: a sample put on a topic's key also
//! goes to any watcher subscribed to it (an observer may read the topics, [`crate::access`]),
//! and processes behind one host's router share one link from here ([`crate::host_router`]);
//! and hearing from a process says it runs, not that it has read what it was handed (under
//! the real clock its figures would keep coming were its subscribers' callbacks blocked;
//! in a ratelab process they wait only on their topic's lock, which a node holds only to
//! read it).
//! Were such a link's queue full all the same (a watcher that stopped reading; a host's
//! router stalled; a process receiving nothing while it reports), Zenoh's thread would
//! wait its 5 s for room, then close that link: the whole star waits those 5 s, where
//! before only the outbox's thread (and, under the virtual clock, the lockstep with it)
//! did. The run goes on, or ends with the processes
//! behind that link gone: a stalled or failed run, never a wrong one.
//!
//! There is an outbox, with its thread, per process the launch passes messages on to
//! ([`Outboxes`]): a process that stops reading (frozen, or slower than its topics) holds
//! only what goes to it, never what goes to the others. Each queue is bounded by bytes
//! ([`MAX_QUEUED_BYTES_PER_PROCESS`], and [`MAX_QUEUED_BYTES`] for them all): past it
//! (under the real clock) samples are dropped, and their subscriber counts them lost on the
//! wire, as a link would.

use crate::{DistError, Keys};
use crossbeam_channel::Sender;
use ratelab_runtime::graph::spec::GraphSpec;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use zenoh::bytes::ZBytes;
use zenoh::Wait;

/// The most bytes of samples the outboxes hold in all; past it a sample handed in is
/// dropped (under the real clock; [`forward_topics`]). A sample is charged at least
/// [`MIN_CHARGE_BYTES`].
pub const MAX_QUEUED_BYTES: usize = 256 * 1024 * 1024;

/// The most bytes of samples the outbox of one process holds; past it a sample for that
/// process is dropped (as past [`MAX_QUEUED_BYTES`]), so that one process that stopped
/// reading leaves room for the others.
pub const MAX_QUEUED_BYTES_PER_PROCESS: usize = 64 * 1024 * 1024;

/// What a sample is charged at least, bytes: a received payload may hold on to one of
/// Zenoh's receive batches (64 KiB) however small it is.
pub const MIN_CHARGE_BYTES: usize = 64 * 1024;

/// The largest message put straight from Zenoh's thread, bytes on the wire ([`wire_bytes`]):
/// a report, a small sample or a reference to a sample in shared memory, never more than a
/// sixteenth of one of Zenoh's batches.
pub const MAX_DIRECT_BYTES: usize = 4 * 1024;

/// The most bytes put straight from Zenoh's thread to one process since it last reported,
/// a quarter of the router's queue for a link (16 batches of 64 KiB); past it, messages to
/// the process take its outbox until it reports again.
pub const MAX_DIRECT_UNANSWERED_BYTES: usize = 256 * 1024;

/// What a reference to a buffer in shared memory takes on the wire, bytes (Zenoh's
/// `ShmBufInfo`: a segment and chunk id, an offset, a length, a generation; about 40).
pub const SHM_REFERENCE_BYTES: usize = 64;
const _: () = assert!(SHM_REFERENCE_BYTES <= MAX_DIRECT_BYTES);

/// What `payload` takes on the wire, bytes: [`SHM_REFERENCE_BYTES`] for each of its buffers
/// in shared memory ([`crate::runs`]: their bytes stay in the publisher's pool), and the
/// length of the rest (a frame drawn into a lent buffer crosses beside its head).
fn wire_bytes(payload: &ZBytes) -> usize {
    crate::runs(payload)
        .map(|(run, shared)| {
            if shared {
                SHM_REFERENCE_BYTES
            } else {
                run.len()
            }
        })
        .sum()
}

/// What `payload` is charged against [`MAX_QUEUED_BYTES`] (in shared memory or not: a
/// queued sample holds its buffer in its publisher's pool).
fn charge(payload: &ZBytes) -> usize {
    payload.len().max(MIN_CHARGE_BYTES)
}

/// A publisher of the launcher's session, shared by the callbacks that hand it messages.
pub(super) type Out = Arc<zenoh::pubsub::Publisher<'static>>;

/// One message to put: where, what, and whether it may be dropped when the outbox is full.
struct Job {
    out: Out,
    payload: ZBytes,
    sample: bool,
}

/// The outbox of one process and its sending thread (which ends once every handle to the
/// outbox is gone).
pub(super) struct Outbox {
    /// The process it passes messages on to.
    process: String,
    tx: Sender<Job>,
    /// Bytes of samples handed in and not yet put, to this process (`.0`) and to all
    /// (`.1`, shared by every outbox of the launch).
    queued: (Arc<AtomicUsize>, Arc<AtomicUsize>),
    /// Whether a dropped sample was said (once).
    said_full: AtomicBool,
    /// What decides whether a message may be put straight from the caller's thread.
    lane: Arc<std::sync::Mutex<Lane>>,
}

/// What decides whether a message may skip the outbox's thread: it may when nothing is
/// queued ahead of it, and its process has not been handed too much since it last
/// reported. Its lock is held across a direct put, so that messages handed in on two
/// threads keep one order.
#[derive(Debug, Default)]
struct Lane {
    /// Messages handed to the outbox's thread and not yet put.
    queued: usize,
    /// Bytes handed in for the process (put directly or queued, each charged
    /// [`PER_MESSAGE_BYTES`] more) since it last reported ([`Lane::answered`]).
    unanswered_bytes: usize,
}

/// What a message handed in takes ([`Lane::hand_in`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Route {
    /// Put from the caller's thread, now.
    Direct,
    /// Queued for the outbox's thread.
    Queue,
}

/// What a message costs in a link's queue beyond its payload (its key and Zenoh's
/// framing), charged against [`MAX_DIRECT_UNANSWERED_BYTES`].
const PER_MESSAGE_BYTES: usize = 64;

impl Lane {
    /// A message of `len` bytes handed in: [`Route::Direct`] when it is small, nothing is
    /// queued ahead of it and it keeps the process within [`MAX_DIRECT_UNANSWERED_BYTES`];
    /// else [`Route::Queue`] (counted until [`Lane::put_done`]). Either way it is charged.
    fn hand_in(&mut self, len: usize) -> Route {
        let charged = self
            .unanswered_bytes
            .saturating_add(len.saturating_add(PER_MESSAGE_BYTES));
        let route = if len <= MAX_DIRECT_BYTES
            && self.queued == 0
            && charged <= MAX_DIRECT_UNANSWERED_BYTES
        {
            Route::Direct
        } else {
            self.queued += 1;
            Route::Queue
        };
        self.unanswered_bytes = charged;
        route
    }

    /// The outbox's thread put a queued message (or it could not be queued).
    fn put_done(&mut self) {
        self.queued = self.queued.saturating_sub(1);
    }

    /// The process reported: what it was handed before is taken as read.
    fn answered(&mut self) {
        self.unanswered_bytes = 0;
    }
}

impl Outbox {
    /// An outbox for `process` and its thread; `all` counts the bytes every outbox holds.
    ///
    /// # Errors
    /// [`DistError::Usage`] when the thread cannot start.
    fn start(process: &str, all: &Arc<AtomicUsize>) -> Result<Arc<Outbox>, DistError> {
        let (tx, rx) = crossbeam_channel::unbounded::<Job>();
        let queued = (Arc::new(AtomicUsize::new(0)), all.clone());
        let counted = queued.clone();
        let lane = Arc::new(std::sync::Mutex::new(Lane::default()));
        let done = lane.clone();
        // Detached: it ends once the outbox is dropped (its channel closed).
        let _detached = std::thread::Builder::new()
            .name(format!("outbox {process}"))
            .spawn(move || {
                for job in rx {
                    let bytes = if job.sample { charge(&job.payload) } else { 0 };
                    // Under congestion control `Block` a put fails only when the session
                    // is closed: the launch is over.
                    let _ = job.out.put(job.payload).wait();
                    counted.0.fetch_sub(bytes, Ordering::SeqCst);
                    counted.1.fetch_sub(bytes, Ordering::SeqCst);
                    ratelab_runtime::graph::lock(&done).put_done();
                }
            })
            .map_err(|e| DistError::Usage(format!("cannot start the launcher's outbox: {e}")))?;
        Ok(Arc::new(Outbox {
            process: process.to_string(),
            tx,
            queued,
            said_full: AtomicBool::new(false),
            lane,
        }))
    }

    /// The process it passes messages on to.
    pub(super) fn process(&self) -> &str {
        &self.process
    }

    /// The launcher heard from the process (a report of its turn under the virtual clock,
    /// its live figures under the real clock): what it was handed before is taken as read,
    /// and the bound on direct puts starts again ([`Lane::answered`]).
    pub(super) fn answered(&self) {
        ratelab_runtime::graph::lock(&self.lane).answered();
    }

    /// Hand in `payload` to put on `out`, from any thread. A small message is put here and
    /// now ([`Lane::hand_in`]), which waits on the lane's lock and, were the link's queue
    /// full, for room (see the module's header); any other is queued for the outbox's
    /// thread, without waiting. A `sample` is dropped when
    /// [`MAX_QUEUED_BYTES_PER_PROCESS`] of samples wait for this process already, or
    /// [`MAX_QUEUED_BYTES`] for all (said once, on stderr).
    pub(super) fn put(&self, out: &Out, payload: ZBytes, sample: bool) {
        let len = if sample { charge(&payload) } else { 0 };
        if sample && !admit(&self.queued, len) {
            if !self.said_full.swap(true, Ordering::Relaxed) {
                eprintln!(
                    "[ratelab] launch: over {} MiB of samples wait to be passed on to process '{}' ({} MiB for all; it reads its topics slower than they come): the rest are dropped, counted lost by their subscribers",
                    MAX_QUEUED_BYTES_PER_PROCESS / (1024 * 1024),
                    self.process,
                    MAX_QUEUED_BYTES / (1024 * 1024)
                );
            }
            return;
        }
        // Under the lane's lock, so that what another thread hands in meanwhile keeps the
        // order (a direct put cannot wait for room: see the module's header).
        let mut lane = ratelab_runtime::graph::lock(&self.lane);
        if lane.hand_in(wire_bytes(&payload)) == Route::Direct {
            // Under congestion control `Block` a put fails only when the session is closed:
            // the launch is over.
            let _ = out.put(payload).wait();
            self.queued.0.fetch_sub(len, Ordering::SeqCst);
            self.queued.1.fetch_sub(len, Ordering::SeqCst);
            return;
        }
        let job = Job {
            out: out.clone(),
            payload,
            sample,
        };
        if self.tx.send(job).is_err() {
            lane.put_done();
            // The thread is gone (it never ends before the outbox): nothing to count.
            self.queued.0.fetch_sub(len, Ordering::SeqCst);
            self.queued.1.fetch_sub(len, Ordering::SeqCst);
        }
    }
}

/// Count `len` bytes more into `queued` (one process's, and all processes') if both stay
/// within their bounds ([`MAX_QUEUED_BYTES_PER_PROCESS`], [`MAX_QUEUED_BYTES`]); `false`
/// (nothing counted) when either would pass it.
fn admit(queued: &(Arc<AtomicUsize>, Arc<AtomicUsize>), len: usize) -> bool {
    let mine = queued.0.fetch_add(len, Ordering::SeqCst) + len;
    let all = queued.1.fetch_add(len, Ordering::SeqCst) + len;
    if mine > MAX_QUEUED_BYTES_PER_PROCESS || all > MAX_QUEUED_BYTES {
        queued.0.fetch_sub(len, Ordering::SeqCst);
        queued.1.fetch_sub(len, Ordering::SeqCst);
        return false;
    }
    true
}

/// The launch's outboxes, one per process, each with its own thread.
pub(super) struct Outboxes(BTreeMap<String, Arc<Outbox>>);

impl Outboxes {
    /// An outbox for each of `processes`.
    ///
    /// # Errors
    /// [`DistError::Usage`] when a thread cannot start.
    pub(super) fn start(processes: &[String]) -> Result<Outboxes, DistError> {
        let all = Arc::new(AtomicUsize::new(0));
        processes
            .iter()
            .map(|p| Ok((p.clone(), Outbox::start(p, &all)?)))
            .collect::<Result<_, DistError>>()
            .map(Outboxes)
    }

    /// The outbox of `process`, if the launch has it.
    pub(super) fn of(&self, process: &str) -> Option<&Arc<Outbox>> {
        self.0.get(process)
    }
}

/// Pass every crossing topic of `spec` (its publisher and subscriber in different
/// processes) through the launcher: hear `@via/<topic>` ([`Keys::via`]; only the
/// publisher's process may put there, [`crate::access`]) and hand each sample to the
/// outbox of its subscriber's process for the topic's key, in the order they came, each a sample the outbox may drop when full
/// only when `droppable` (the real clock: under the virtual clock its subscriber waits for
/// it, and the lockstep's horizon bounds what waits). Keep the subscribers.
///
/// # Errors
/// [`DistError::Zenoh`] when a publisher or subscriber cannot be declared.
pub(super) fn forward_topics(
    session: &zenoh::Session,
    keys: &Keys,
    spec: &GraphSpec,
    outboxes: &Outboxes,
    droppable: bool,
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, DistError> {
    let block = zenoh::qos::CongestionControl::Block;
    let mut subscribers = Vec::new();
    for t in &spec.topics {
        let Some(reader) = t.subscriber() else {
            continue;
        };
        let to = spec.process_of(reader);
        if spec.process_of(t.publisher) == to {
            continue;
        }
        let Some(outbox) = outboxes.of(&to) else {
            continue; // not a process of this launch: nothing to pass on to
        };
        let out: Out = Arc::new(
            session
                .declare_publisher(keys.topic(&t.name))
                .congestion_control(block)
                .wait()?,
        );
        let outbox = outbox.clone();
        let subscriber = session
            .declare_subscriber(keys.via(&t.name))
            .callback(move |s| outbox.put(&out, s.payload().clone(), droppable))
            .wait()?;
        subscribers.push(subscriber);
    }
    Ok(subscribers)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A process that stopped reading fills its own bound, and the others still have room,
    /// up to the bound of all.
    #[test]
    fn one_process_s_full_queue_leaves_room_for_the_others() {
        let all = Arc::new(AtomicUsize::new(0));
        let queue = || (Arc::new(AtomicUsize::new(0)), all.clone());
        let (frozen, other) = (queue(), queue());
        let mib = 1024 * 1024;
        let per = MAX_QUEUED_BYTES_PER_PROCESS / mib;
        for _ in 0..per {
            assert!(admit(&frozen, mib));
        }
        assert!(!admit(&frozen, mib), "past its own bound");
        assert_eq!(
            frozen.0.load(Ordering::SeqCst),
            MAX_QUEUED_BYTES_PER_PROCESS
        );
        assert!(admit(&other, mib), "another process still has room");
        // Processes enough to fill the bound of all: then nobody has room.
        let mut queues = vec![frozen, other];
        while all.load(Ordering::SeqCst) + mib <= MAX_QUEUED_BYTES {
            let q = queues.last().unwrap().clone();
            if !admit(&q, mib) {
                queues.push(queue());
            }
        }
        assert_eq!(all.load(Ordering::SeqCst), MAX_QUEUED_BYTES);
        assert!(!admit(&queue(), mib), "past the bound of all");
        assert_eq!(all.load(Ordering::SeqCst), MAX_QUEUED_BYTES);
    }

    /// A message skips the outbox's thread only when small, with nothing queued ahead of it
    /// (the order), and within what its process may be handed unanswered.
    #[test]
    fn the_direct_lane_keeps_order_and_its_bound() {
        let mut lane = Lane::default();
        assert_eq!(lane.hand_in(100), Route::Direct);
        assert_eq!(lane.unanswered_bytes, 100 + PER_MESSAGE_BYTES);
        // A large message is queued; a small one after it waits behind it, until the
        // outbox's thread has put it.
        assert_eq!(lane.hand_in(MAX_DIRECT_BYTES + 1), Route::Queue);
        assert_eq!(lane.hand_in(10), Route::Queue, "behind the large one");
        lane.put_done();
        assert_eq!(lane.hand_in(10), Route::Queue, "one still queued");
        lane.put_done();
        assert_eq!(lane.hand_in(10), Route::Queue, "one still queued");
        lane.put_done();
        lane.put_done();
        assert_eq!(lane.queued, 0);
        assert_eq!(lane.hand_in(10), Route::Direct, "nothing ahead of it");
        // Queued messages count against the bound too.
        lane.answered();
        for _ in 0..MAX_DIRECT_UNANSWERED_BYTES / (MAX_DIRECT_BYTES + 1) {
            lane.hand_in(MAX_DIRECT_BYTES + 1);
            lane.put_done();
        }
        assert_eq!(lane.hand_in(10), Route::Queue, "over the bound: {lane:?}");
        lane.put_done();
        lane.answered();
        assert_eq!(lane.hand_in(10), Route::Direct, "answered");
        // At the bound exactly, direct; one byte past it, queued.
        lane.answered();
        let exact = MAX_DIRECT_UNANSWERED_BYTES - PER_MESSAGE_BYTES;
        lane.unanswered_bytes = exact - MAX_DIRECT_BYTES;
        assert_eq!(lane.hand_in(MAX_DIRECT_BYTES), Route::Direct);
        assert_eq!(lane.unanswered_bytes, MAX_DIRECT_UNANSWERED_BYTES);
        lane.answered();
        lane.unanswered_bytes = exact - MAX_DIRECT_BYTES + 1;
        assert_eq!(lane.hand_in(MAX_DIRECT_BYTES), Route::Queue);
    }

    /// Hearing from its process starts an outbox's bound again.
    #[test]
    fn hearing_from_the_process_starts_the_bound_again() {
        let all = Arc::new(AtomicUsize::new(0));
        let outbox = Outbox::start("p", &all).unwrap();
        ratelab_runtime::graph::lock(&outbox.lane).unanswered_bytes = 7;
        outbox.answered();
        assert_eq!(
            ratelab_runtime::graph::lock(&outbox.lane).unanswered_bytes,
            0
        );
    }

    /// A sample in shared memory is charged the lane its reference, not its bytes; any
    /// other payload its length.
    #[test]
    fn a_sample_in_shared_memory_is_a_reference_on_the_wire() {
        use zenoh::shm::{Defragment, GarbageCollect, ShmProviderBuilder};
        assert_eq!(wire_bytes(&ZBytes::from(vec![0u8; 100_000])), 100_000);
        let Ok(pool) = ShmProviderBuilder::default_backend(1 << 20).wait() else {
            eprintln!("no shared memory here: the reference's charge is not checked");
            return;
        };
        let buffer = pool
            .alloc(256 * 1024)
            .with_policy::<Defragment<GarbageCollect>>()
            .wait()
            .unwrap();
        let payload = ZBytes::from(buffer);
        assert_eq!(payload.len(), 256 * 1024);
        assert_eq!(wire_bytes(&payload), SHM_REFERENCE_BYTES);
        // So a frame in shared memory takes the direct lane, however large.
        assert_eq!(Lane::default().hand_in(wire_bytes(&payload)), Route::Direct);
        // A frame a node drew into a lent buffer crosses beside its head: the head is
        // charged its length, the frame a reference.
        let mut pieces = ZBytes::writer();
        std::io::Write::write_all(&mut pieces, &[7u8; 30]).unwrap();
        pieces.append(payload);
        let pieces = pieces.finish();
        assert_eq!(wire_bytes(&pieces), 30 + SHM_REFERENCE_BYTES);
        assert_eq!(Lane::default().hand_in(wire_bytes(&pieces)), Route::Direct);
        // Runs all shorter than the threshold (a sample fragmented over the socket) are
        // charged their length.
        let mut runs = ZBytes::writer();
        runs.append(ZBytes::from(vec![0u8; 60_000]));
        runs.append(ZBytes::from(vec![0u8; 60_000]));
        assert_eq!(wire_bytes(&runs.finish()), 120_000);
    }

    #[test]
    fn a_small_sample_is_charged_a_receive_batch() {
        assert_eq!(charge(&ZBytes::from(vec![0u8; 10])), MIN_CHARGE_BYTES);
        assert_eq!(charge(&ZBytes::from(vec![0u8; 100_000])), 100_000);
    }
}
