//! What the launcher passes on to the processes from Zenoh's thread, sent from a thread of
//! its own: the crossing topics' samples and the lockstep's relayed reports.
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
//! The queue is bounded by bytes ([`MAX_QUEUED_BYTES`]): past it (a process that reads its
//! topics slower than they are published, under the real clock) samples are dropped, and
//! their subscriber counts them lost on the wire, as a link would.

use crate::{DistError, Keys};
use crossbeam_channel::Sender;
use ratelab_runtime::graph::spec::GraphSpec;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use zenoh::bytes::ZBytes;
use zenoh::Wait;

/// The most bytes of samples the outbox holds; past it a sample handed in is dropped
/// (under the real clock; [`forward_topics`]). A sample is charged at least
/// [`MIN_CHARGE_BYTES`].
pub const MAX_QUEUED_BYTES: usize = 256 * 1024 * 1024;

/// What a sample is charged at least, bytes: a received payload may hold on to one of
/// Zenoh's receive batches (64 KiB) however small it is.
pub const MIN_CHARGE_BYTES: usize = 64 * 1024;

/// What `payload` is charged against [`MAX_QUEUED_BYTES`].
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

/// The launcher's outbox and its sending thread (which ends once every handle to the
/// outbox is gone).
pub(super) struct Outbox {
    tx: Sender<Job>,
    /// Bytes of samples handed in and not yet put.
    queued: Arc<AtomicUsize>,
    /// Whether a dropped sample was said (once).
    said_full: AtomicBool,
}

impl Outbox {
    /// An outbox and its thread.
    ///
    /// # Errors
    /// [`DistError::Usage`] when the thread cannot start.
    pub(super) fn start() -> Result<Arc<Outbox>, DistError> {
        let (tx, rx) = crossbeam_channel::unbounded::<Job>();
        let queued = Arc::new(AtomicUsize::new(0));
        let counted = queued.clone();
        // Detached: it ends once the outbox is dropped (its channel closed).
        let _detached = std::thread::Builder::new()
            .name("launcher outbox".into())
            .spawn(move || {
                for job in rx {
                    let bytes = if job.sample { charge(&job.payload) } else { 0 };
                    // Under congestion control `Block` a put fails only when the session
                    // is closed: the launch is over.
                    let _ = job.out.put(job.payload).wait();
                    counted.fetch_sub(bytes, Ordering::SeqCst);
                }
            })
            .map_err(|e| DistError::Usage(format!("cannot start the launcher's outbox: {e}")))?;
        Ok(Arc::new(Outbox {
            tx,
            queued,
            said_full: AtomicBool::new(false),
        }))
    }

    /// Hand in `payload` to put on `out` (from any thread, never waiting). A `sample` is
    /// dropped when [`MAX_QUEUED_BYTES`] of samples wait already (said once, on stderr).
    pub(super) fn put(&self, out: &Out, payload: ZBytes, sample: bool) {
        if sample {
            let len = charge(&payload);
            if self.queued.fetch_add(len, Ordering::SeqCst) + len > MAX_QUEUED_BYTES {
                self.queued.fetch_sub(len, Ordering::SeqCst);
                if !self.said_full.swap(true, Ordering::Relaxed) {
                    eprintln!(
                        "[ratelab] launch: over {} MiB of samples wait to be passed on (a process reads its topics slower than they come): the rest are dropped, counted lost by their subscribers",
                        MAX_QUEUED_BYTES / (1024 * 1024)
                    );
                }
                return;
            }
        }
        let job = Job {
            out: out.clone(),
            payload,
            sample,
        };
        if let Err(e) = self.tx.send(job) {
            // The thread is gone (it never ends before the outbox): nothing to count.
            if e.0.sample {
                self.queued
                    .fetch_sub(charge(&e.0.payload), Ordering::SeqCst);
            }
        }
    }
}

/// Pass every crossing topic of `spec` (its publisher and subscriber in different
/// processes) through the launcher: hear `@via/<topic>` ([`Keys::via`]; only the
/// publisher's process may put there, [`crate::access`]) and hand each sample to `outbox`
/// for the topic's key, in the order they came, each a sample the outbox may drop when full
/// only when `droppable` (the real clock: under the virtual clock its subscriber waits for
/// it, and the lockstep's horizon bounds what waits). Keep the subscribers.
///
/// # Errors
/// [`DistError::Zenoh`] when a publisher or subscriber cannot be declared.
pub(super) fn forward_topics(
    session: &zenoh::Session,
    keys: &Keys,
    spec: &GraphSpec,
    outbox: &Arc<Outbox>,
    droppable: bool,
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, DistError> {
    let block = zenoh::qos::CongestionControl::Block;
    let mut subscribers = Vec::new();
    for t in &spec.topics {
        let Some(reader) = t.subscriber() else {
            continue;
        };
        if spec.process_of(t.publisher) == spec.process_of(reader) {
            continue;
        }
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
