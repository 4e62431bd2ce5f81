//! A process's shared memory for its large samples (an image, a scan:
//! [`SHM_THRESHOLD_BYTES`] or more, issue 76): its pool ([`SharedPool`]), the buffers it lends
//! a node to draw a frame into (ROS 2's loaned messages: [`Lender`]), a sample written into
//! it once ([`SharedPool::written`]), and a sample read in place on arrival
//! ([`read_arrived`]): its pixels stay a view of the shared buffer unless the node must own a
//! copy.
//!
//! A frame drawn into a lent buffer is never copied on its way: the sample goes out as a
//! small run (its head and the message's other fields) followed by the buffer itself, which
//! Zenoh passes by reference, and the receiver reads it in those pieces.

use super::*;
use crate::wire::{SampleHead, SampleView};
use crate::{SHM_POOL_BYTES, SHM_THRESHOLD_BYTES};
use ratelab_core::msg::MsgData;
use ratelab_core::pixels::{Lender, LentPixels};
use ratelab_runtime::graph::lock;
use std::io::Write;
use std::sync::Weak;
use zenoh::bytes::ZBytes;
use zenoh::shm::{
    Defragment, GarbageCollect, PosixShmProviderBackend, ShmProvider, ShmProviderBuilder, ZShm,
    ZShmMut,
};

/// A process's shared-memory pool for its large samples: its own ([`SHM_POOL_BYTES`], made
/// as the process starts when it publishes a topic whose message type has a field of bytes,
/// else in the background when the first large sample is sent; Zenoh's copying of large payloads
/// into a pool of its own is off, [`crate::open_session`]). A buffer returns to it only when
/// no process holds it any more (Zenoh's safe garbage collection): a subscriber keeps a
/// frame's buffer as long as it keeps the message, as its pixels ([`read_arrived`]), and
/// the bytes must not change under it.
pub(super) struct SharedPool {
    /// Shared memory is on ([`crate::shared_memory`]).
    enabled: bool,
    /// The pool once made (`Some(None)`: it could not be made; large samples cross the
    /// socket).
    provider: Arc<std::sync::OnceLock<Option<ShmProvider<PosixShmProviderBackend>>>>,
    /// Whether the pool is being made.
    started: std::sync::atomic::AtomicBool,
    /// The frames lent from the pool that some holder still keeps ([`Lender::lend`]): a
    /// sample tells one by its address and passes it on as it lies ([`SharedPool::written`]).
    lent: Arc<Mutex<Vec<Weak<LentFrame>>>>,
}

impl SharedPool {
    /// A pool, when `enabled` (shared memory on), made when first needed.
    pub(super) fn new(enabled: bool) -> Arc<SharedPool> {
        Arc::new(SharedPool {
            enabled,
            provider: Arc::default(),
            started: std::sync::atomic::AtomicBool::new(false),
            lent: Arc::default(),
        })
    }

    /// Whether shared memory is on for it.
    pub(super) fn enabled(&self) -> bool {
        self.enabled
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
    /// [`MsgData::encoded_len`]), written once, with its length:
    /// - in pieces when `data` holds a frame lent from this pool (drawn there by its node,
    ///   [`Lender::lend`]): the bytes around the frame copied into a small run, the frame
    ///   passed on as it lies, never copied ([`SharedPool::in_pieces`]);
    /// - else into a buffer of the pool when [`SharedPool::buffer`] gives one;
    /// - else into bytes of its own.
    ///
    /// `None` only if `payload_len` is not the payload's length.
    pub(super) fn written(
        &self,
        head: &SampleHead,
        data: &MsgData,
        payload_len: usize,
    ) -> Option<(ZBytes, usize)> {
        let len = head.sample_len(payload_len);
        if let Some(pieces) = self.in_pieces(head, data, payload_len) {
            return Some((pieces, len));
        }
        if let Some(mut shared) = self.buffer(len) {
            let written = head.write(data, payload_len, &mut shared);
            return written.ok().map(|()| (shared.into(), len));
        }
        let mut own = vec![0; len];
        let written = head.write(data, payload_len, &mut own);
        written.ok().map(|()| (own.into(), len))
    }

    /// The sample in pieces when `data` holds a frame lent from this pool: each frame the
    /// lent buffer itself, and the bytes before, between and after the frames (the head
    /// first) in runs of their own, copied (Zenoh passes a shared-memory run of a sample
    /// by reference and the others by value, `zenoh-codec`'s sliced `ZBuf`). `None` when it
    /// holds none (nothing is lent now, or not this message's bytes: found by a first walk
    /// of the encoding, which copies nothing, so such a message is still written once), or
    /// its payload is not `payload_len` bytes.
    fn in_pieces(&self, head: &SampleHead, data: &MsgData, payload_len: usize) -> Option<ZBytes> {
        if payload_len < SHM_THRESHOLD_BYTES || !self.lends_now() {
            return None;
        }
        let mut holds = false;
        data.encode_pieces(&mut |piece| holds |= self.lent_frame(piece).is_some())
            .ok()?;
        if !holds {
            return None;
        }
        let mut out = ZBytes::writer();
        out.write_all(&head.head_bytes(payload_len)).ok()?;
        let mut n = 0;
        data.encode_pieces(&mut |piece| {
            n += piece.len();
            match self.lent_frame(piece) {
                Some(frame) => out.append(frame.into()),
                None => out.write_all(piece).unwrap_or_default(),
            }
        })
        .ok()?;
        (n == payload_len).then(|| out.finish())
    }

    /// Whether a frame lent from the pool is still held (by a message being published, a
    /// queue): the register's dead entries are let go here too.
    fn lends_now(&self) -> bool {
        let mut lent = lock(&self.lent);
        lent.retain(|w| w.strong_count() > 0);
        !lent.is_empty()
    }

    /// The lent frame whose bytes `bytes` are (the same address and length), if any.
    fn lent_frame(&self, bytes: &[u8]) -> Option<ZShm> {
        if bytes.len() < SHM_THRESHOLD_BYTES {
            return None;
        }
        lock(&self.lent).iter().find_map(|w| {
            let frame = w.upgrade()?;
            let lies = frame.0.as_ptr() == bytes.as_ptr() && frame.0.len() == bytes.len();
            lies.then(|| frame.0.clone())
        })
    }
}

impl Lender for SharedPool {
    /// A buffer of the pool when [`SharedPool::buffer`] gives one (it may hold an earlier
    /// frame: [`ratelab_core::pixels::PixelBuffer::lent`] zeroes it).
    fn lend(&self, len: usize) -> Option<Box<dyn LentPixels>> {
        let buffer = self.buffer(len)?;
        Some(Box::new(Lending {
            buffer,
            lent: self.lent.clone(),
        }))
    }
}

/// A buffer of the pool lent to a node, being drawn into.
struct Lending {
    buffer: ZShmMut,
    /// Its pool's register of lent frames.
    lent: Arc<Mutex<Vec<Weak<LentFrame>>>>,
}

/// A frame drawn into a lent buffer, shared from then on: its pixels' owner
/// ([`bytes::Bytes::from_owner`]), which the pool's register knows by address.
struct LentFrame(ZShm);

impl AsRef<[u8]> for LentFrame {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

/// A shared [`LentFrame`], as [`bytes::Bytes::from_owner`] takes it.
struct FrameOwner(Arc<LentFrame>);

impl AsRef<[u8]> for FrameOwner {
    fn as_ref(&self) -> &[u8] {
        &self.0 .0
    }
}

impl LentPixels for Lending {
    fn bytes_mut(&mut self) -> &mut [u8] {
        &mut self.buffer
    }
    fn bytes(&self) -> &[u8] {
        &self.buffer
    }
    fn freeze(self: Box<Self>) -> bytes::Bytes {
        let frame = Arc::new(LentFrame(self.buffer.into()));
        let mut lent = lock(&self.lent);
        lent.retain(|w| w.strong_count() > 0);
        lent.push(Arc::downgrade(&frame));
        bytes::Bytes::from_owner(FrameOwner(frame))
    }
}

/// Read a sample as it arrived, in place, and hand it to `read` with the buffer its frame
/// can be a view of ([`SampleView::deliver`]'s `arrived`), if any:
/// - one run of bytes in shared memory: read where it is, the whole run the buffer;
/// - several runs (a head, and a frame a node drew into a buffer it was lent,
///   [`SharedPool::written`]): read in pieces, its run in shared memory
///   ([`crate::shared_run`]) the buffer;
/// - anything else: Zenoh's bytes, its pixels copied.
///
/// Only a launch's processes may put on a topic's key (its access control), and each writes
/// into a [`SharedPool`], whose buffers are never reclaimed while held: a view stays valid.
/// A view keeps the whole payload, so a frame that arrived in pieces also keeps the receive
/// batch its head arrived in (Zenoh's API cannot split a payload; a batch is at most 64 KiB,
/// and Zenoh makes another when its pool of them is empty): one per frame held, as in a
/// queue or the zero-order hold.
///
/// A payload over [`crate::wire::MAX_SAMPLE_BYTES`] is refused before its runs are looked at.
pub(super) fn read_arrived<R>(
    payload: &ZBytes,
    read: impl FnOnce(Result<SampleView<'_>, String>, Option<&bytes::Bytes>) -> R,
) -> R {
    if let Err(e) = crate::wire::check_sample_len(payload.len()) {
        return read(Err(e), None);
    }
    let shared =
        crate::shared_run(payload).map(|i| bytes::Bytes::from_owner(NthSlice(payload.clone(), i)));
    let mut runs = payload.slices();
    let first = runs.next().unwrap_or_default();
    if runs.next().is_none() {
        // One run (every small sample): read where it is, no list of runs made.
        let bytes = shared.as_deref().unwrap_or(first);
        return read(SampleView::decode(bytes), shared.as_ref());
    }
    let pieces: Vec<&[u8]> = payload.slices().collect();
    read(SampleView::decode_pieces(&pieces), shared.as_ref())
}

/// One run of a payload's bytes, as [`bytes::Bytes::from_owner`] takes it: the payload is
/// kept, so the run stays where it is.
struct NthSlice(ZBytes, usize);

impl AsRef<[u8]> for NthSlice {
    fn as_ref(&self) -> &[u8] {
        self.0.slices().nth(self.1).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::msg::{AnyTopic, ImageMsg, Message};
    use ratelab_core::pixels::{ImageData, PixelBuffer};

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
                let (seq, pieces, shared) = read_arrived(s.payload(), |view, shared| {
                    let view = view.expect("a sample");
                    let offset = &mut lock(&offset);
                    view.deliver(&t, offset, shared).expect("delivered");
                    let pieces = matches!(view.data, crate::wire::Payload::Pieces { .. });
                    (view.head.seq, pieces, shared.cloned())
                });
                let data = t.read(Nanos(u64::MAX / 2)).expect("published").data;
                let _ = tx.send((seq, pieces, shared, data));
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
        let image = |data: ImageData| {
            MsgData::new(ImageMsg {
                height: 480,
                width: 640,
                encoding: "mono8".into(),
                step: 640,
                data,
            })
        };
        let draw = |seq: u64, px: &mut [u8]| {
            for (i, p) in px.iter_mut().enumerate() {
                *p = (i as u64 + seq) as u8;
            }
        };
        let frame = |seq: u64| {
            let mut px = vec![0u8; 640 * 480];
            draw(seq, &mut px);
            image(px.into())
        };
        let head = |seq: u64| SampleHead {
            seq,
            stamp_ns: seq,
            origin_ns: None,
            sent_mono_ns: wire::mono_now_ns(),
        };
        // The pool is made when first asked, in the background: until it is ready the
        // frames cross the socket (and still arrive).
        let mut seq = 0;
        let (sent, got) = loop {
            assert!(Instant::now() < deadline, "the pool was never ready");
            let data = frame(seq);
            let (bytes, _) = pool
                .written(&head(seq), &data, data.encoded_len())
                .expect("written");
            let in_pool = bytes.as_shm().is_some();
            publisher.put(bytes).wait().unwrap();
            let got = rx.recv_timeout(Duration::from_secs(10)).expect("arrived");
            assert_eq!(got.0, seq);
            assert_eq!(got.3, data, "the frame, whole");
            if in_pool {
                break (data, got);
            }
            seq += 1;
            std::thread::sleep(Duration::from_millis(50));
        };
        let (_, pieces, shared, data) = got;
        assert!(
            !pieces,
            "a frame of the node's own memory is copied into one run"
        );
        let shared = shared.expect("the frame arrived in shared memory");
        let img = data.get::<ImageMsg>().unwrap();
        assert!(
            img.data.is_within(&shared),
            "the pixels are a view of the shared buffer"
        );
        assert!(!img.data.shares(&sent.get::<ImageMsg>().unwrap().data));

        // A frame drawn into a buffer the pool lent is not copied at all: the sample is its
        // head and the buffer itself, and the receiver's pixels are a view of that buffer.
        let lender: Arc<dyn Lender> = pool.clone();
        topic.set_lender(lender.clone());
        seq += 1;
        let mut px = topic.loan_pixels(640 * 480);
        assert!(px.is_lent() && px.iter().all(|&b| b == 0), "lent, zeroed");
        draw(seq, &mut px);
        let drawn = ImageData::from(px);
        let data = image(drawn.clone());
        let h = head(seq);
        let (bytes, len) = pool
            .written(&h, &data, data.encoded_len())
            .expect("written");
        assert_eq!(len, bytes.len());
        let runs: Vec<&[u8]> = bytes.slices().collect();
        assert_eq!(runs.len(), 2, "the head, then the frame");
        assert!(
            drawn.is_within(runs[1]) && runs[1].len() == drawn.len(),
            "the lent buffer itself crosses"
        );
        let mut one = vec![0; len];
        h.write(&data, data.encoded_len(), &mut one).unwrap();
        assert_eq!(bytes.to_bytes(), one, "the same bytes as in one run");
        publisher.put(bytes).wait().unwrap();
        let (got_seq, pieces, shared, got) =
            rx.recv_timeout(Duration::from_secs(10)).expect("arrived");
        assert_eq!((got_seq, &got), (seq, &data), "the frame, whole");
        assert!(pieces, "read in pieces");
        let shared = shared.expect("the frame is a view of shared memory");
        let img = got.get::<ImageMsg>().unwrap();
        assert!(img.data.is_within(&shared) && img.data.len() == shared.len());
        // A message that holds no lent frame is written whole, as before.
        let other = frame(seq + 1);
        let (bytes, _) = pool
            .written(&head(seq + 1), &other, other.encoded_len())
            .unwrap();
        assert!(bytes.as_shm().is_some());
        drop((drawn, data, got));

        // A buffer of the pool that held an earlier frame is lent zeroed.
        if let Some(mut dirty) = lender.lend(640 * 480) {
            dirty.bytes_mut().fill(0xFF); // and back to the pool
        }
        let px = PixelBuffer::lent(Some(&*lender), 640 * 480);
        assert!(px.is_lent() && px.iter().all(|&b| b == 0));
        drop(px);

        // A small message (a force) is not put in the pool: it crosses the socket.
        let force = MsgData::new(ratelab_core::msg::ForceMsg { newtons: 1.0 });
        let (small, _) = pool.written(&head(0), &force, force.encoded_len()).unwrap();
        assert!(small.as_shm().is_none());
        // Nor is a small frame lent.
        assert!(!PixelBuffer::lent(Some(&*lender), 1000).is_lent());
        // With shared memory off, nothing is put in a pool, or lent.
        let big = frame(0);
        let off = SharedPool::new(false);
        assert!(off.buffer(head(0).sample_len(big.encoded_len())).is_none());
        assert!(off.lend(640 * 480).is_none());
        let (own, len) = off.written(&head(0), &big, big.encoded_len()).unwrap();
        assert!(own.as_shm().is_none());
        assert_eq!(len, head(0).sample_len(big.encoded_len()));
        // A payload length that is not the payload's writes nothing.
        assert!(off.written(&head(0), &big, big.encoded_len() + 1).is_none());
    }
}
