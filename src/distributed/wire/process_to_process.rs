//! Process to process: a crossing topic's samples ([`WireSample`], on the topic's key, from
//! its publisher's process to its subscriber's, through the launcher's router) and, under
//! the virtual clock, the tick reports of each process's events ([`Ticked`], several to a
//! message, to the launcher, which hands them to the other processes in their turn). Both
//! postcard, both bounded and decoded exactly. A sample is written from its head and its
//! message without an intermediate copy ([`SampleHead::write`]) and read without copying its
//! payload ([`SampleView`]).

use super::decode_exact;
use ratelab_core::limits;
use ratelab_core::msg::{AnyTopic, MsgData, PiecesError};
use ratelab_core::time::Nanos;
use serde::{Deserialize, Serialize};

pub use ratelab_core::limits::MAX_SAMPLE_BYTES;

/// The largest sequence number accepted: an hour at 10 kHz is 3.6 × 10⁷ messages; this
/// leaves room and keeps every counter far from overflow.
pub const MAX_SEQ: u64 = 1 << 40;

/// The most a subscriber accepts a publisher's `seq` to move ahead of the last it received:
/// a gap up to this is counted as lost on the wire, a larger one refused
/// ([`WireSample::deliver`]). A 10 000 Hz publisher takes 100 s to publish this many.
pub const MAX_SEQ_JUMP: u64 = 1_000_000;

/// What a topic sample says before its payload: its numbers and stamps. Postcard writes a
/// struct as its fields one after another, so a [`WireSample`] is this head, the payload's
/// length and the payload, and a sample can be written in place ([`SampleHead::write`])
/// or read in place ([`SampleView`]) with the same bytes on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SampleHead {
    /// The publisher's sequence number for the topic (from 0).
    pub seq: u64,
    /// Run time of the publish, ns (the graph's processes share the run's clock).
    pub stamp_ns: u64,
    /// The origin stamp (the sensor reading it derives from), ns.
    pub origin_ns: Option<u64>,
    /// When it was sent, on the host's `CLOCK_MONOTONIC`, ns: receive time minus this is
    /// the over-the-wire latency (exact on one host; across hosts, see docs/distributed.md).
    pub sent_mono_ns: u64,
}

impl SampleHead {
    /// The bytes of the sample this head and a payload of `payload_len` bytes make
    /// ([`WireSample::encode`]'s length; `payload_len` is [`MsgData::encoded_len`], found
    /// without encoding the payload, once per sample by the caller).
    pub fn sample_len(&self, payload_len: usize) -> usize {
        self.head_len(payload_len) + payload_len
    }

    /// The bytes of the head before a payload of `payload_len` bytes (the head, then the
    /// payload's length as postcard writes a sequence's).
    fn head_len(&self, payload_len: usize) -> usize {
        postcard::experimental::serialized_size(&(self, payload_len)).unwrap_or(0)
    }

    /// The bytes before a payload of `payload_len` bytes: the head, then the payload's
    /// length (a sample written in pieces, its payload after them, [`Payload::Pieces`]).
    pub fn head_bytes(&self, payload_len: usize) -> Vec<u8> {
        postcard::to_allocvec(&(self, payload_len)).unwrap_or_default()
    }

    /// Write the sample of this head and `payload` (`payload_len` bytes encoded,
    /// [`MsgData::encoded_len`]) into `out`, which must be exactly [`SampleHead::sample_len`]
    /// long (a shared-memory buffer, so that a large message is written once, straight from
    /// the message): the same bytes as [`WireSample::encode`].
    ///
    /// # Errors
    /// `out` is not [`SampleHead::sample_len`] long, or the payload does not encode to
    /// `payload_len` bytes.
    pub fn write(
        &self,
        payload: &MsgData,
        payload_len: usize,
        out: &mut [u8],
    ) -> Result<(), String> {
        let head_len = self.head_len(payload_len);
        if out.len() != head_len + payload_len {
            return Err(format!(
                "a sample of {} bytes in {}",
                head_len + payload_len,
                out.len()
            ));
        }
        let (head, rest) = out.split_at_mut(head_len);
        postcard::to_slice(&(self, payload_len), head)
            .map_err(|e| format!("a sample's head: {e}"))?;
        if payload.encode_into(rest)? != payload_len {
            return Err(format!("a sample's payload of {payload_len} bytes"));
        }
        Ok(())
    }
}

/// A sample of `len` bytes may be read: at most [`MAX_SAMPLE_BYTES`].
///
/// # Errors
/// One line naming the bound.
pub fn check_sample_len(len: usize) -> Result<(), String> {
    if len > MAX_SAMPLE_BYTES {
        return Err(limits::refusal(
            format_args!("a sample of {len} bytes (at most {MAX_SAMPLE_BYTES})"),
            "MAX_SAMPLE_BYTES",
        ));
    }
    Ok(())
}

/// One topic sample on the wire, owning its payload: its [`SampleHead`], then the payload.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireSample {
    /// Its numbers and stamps.
    pub head: SampleHead,
    /// The payload: the message in its type's wire encoding ([`ratelab_core::msg::MsgData::to_bytes`]),
    /// decoded by the receiving topic's type ([`ratelab_core::msg::MsgType::decode`]), exactly.
    /// Written as one run of bytes (postcard's length and the bytes, as a sequence of bytes
    /// is written, so the wire is the same), copied whole rather than byte by byte.
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}

/// One topic sample read in place: its head, and its payload borrowed from the bytes that
/// arrived ([`SampleView::decode`], [`SampleView::decode_pieces`]), not copied.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleView<'a> {
    /// Its numbers and stamps.
    pub head: SampleHead,
    /// The payload, as in [`WireSample::data`].
    pub data: Payload<'a>,
}

/// A sample's payload as it arrived: one run of bytes, or the rest of the run its head came
/// in followed by further runs (a frame that crossed in a shared-memory buffer of its own
/// beside its head, written by its publisher's node straight into a buffer it was lent).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Payload<'a> {
    /// One run of bytes.
    One(&'a [u8]),
    /// Several, in order: the bytes after the head in its run, then the runs after it.
    Pieces {
        /// The bytes after the head, in the run the head came in.
        first: &'a [u8],
        /// The runs after it.
        rest: &'a [&'a [u8]],
    },
}

impl Payload<'_> {
    /// Its bytes in all.
    pub fn len(&self) -> usize {
        match self {
            Payload::One(b) => b.len(),
            Payload::Pieces { first, rest } => {
                first.len() + rest.iter().map(|p| p.len()).sum::<usize>()
            }
        }
    }

    /// Whether it has no bytes.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Its bytes as one run (copied).
    pub fn to_vec(&self) -> Vec<u8> {
        match self {
            Payload::One(b) => b.to_vec(),
            Payload::Pieces { first, rest } => {
                let mut all = Vec::with_capacity(self.len());
                all.extend_from_slice(first);
                rest.iter().for_each(|p| all.extend_from_slice(p));
                all
            }
        }
    }

    /// The message it holds, of type `ty`: read in pieces where it came in pieces (a field
    /// of bytes borrowed from the run it lies in), or, should a field straddle two runs
    /// (no ratelab process writes one so), from the runs joined.
    fn decode(&self, ty: ratelab_core::msg::MsgType) -> Result<MsgData, String> {
        match self {
            Payload::One(b) => ty.decode(b),
            Payload::Pieces { first, rest } => {
                let mut pieces = Vec::with_capacity(rest.len() + 1);
                pieces.push(*first);
                pieces.extend_from_slice(rest);
                match ty.decode_pieces(&pieces) {
                    Err(PiecesError::Straddles) => ty.decode(&self.to_vec()),
                    Err(PiecesError::Refused(why)) => Err(why),
                    Ok(data) => Ok(data),
                }
            }
        }
    }
}

/// A sample as postcard reads it in one run: its head and its payload, borrowed.
#[derive(Deserialize)]
struct OneRun<'a> {
    head: SampleHead,
    data: &'a [u8],
}

impl<'a> SampleView<'a> {
    /// Read a sample in place, refusing anything over [`MAX_SAMPLE_BYTES`] or malformed: it
    /// must decode exactly (no byte after its end), and a `seq` beyond [`MAX_SEQ`] is
    /// refused too (no run publishes that many, and counters must not overflow).
    ///
    /// # Errors
    /// One line.
    pub fn decode(bytes: &'a [u8]) -> Result<SampleView<'a>, String> {
        check_sample_len(bytes.len())?;
        let s: OneRun<'a> = decode_exact(bytes, MAX_SAMPLE_BYTES, "sample")?;
        SampleView {
            head: s.head,
            data: Payload::One(s.data),
        }
        .checked()
    }

    /// Read a sample that arrived in several runs of bytes, in order (its head and a frame
    /// in a shared-memory buffer of its own, [`Payload::Pieces`]), in place: as
    /// [`SampleView::decode`] of the runs joined, without joining them. The head must lie
    /// in the first run.
    ///
    /// # Errors
    /// As [`SampleView::decode`]; a head that does not fit in the first run.
    pub fn decode_pieces(pieces: &'a [&'a [u8]]) -> Result<SampleView<'a>, String> {
        let Some((&first, rest)) = pieces.split_first() else {
            return Err("an empty sample".into());
        };
        let len = first.len() + rest.iter().map(|p| p.len()).sum::<usize>();
        check_sample_len(len)?;
        let ((head, payload_len), first): ((SampleHead, usize), &[u8]) =
            postcard::take_from_bytes(first).map_err(|e| format!("a malformed sample: {e}"))?;
        let data = Payload::Pieces { first, rest };
        if payload_len != data.len() {
            return Err(format!(
                "a malformed sample: a payload of {payload_len} bytes in {}",
                data.len()
            ));
        }
        SampleView { head, data }.checked()
    }

    /// Itself, or why its `seq` is refused.
    fn checked(self) -> Result<SampleView<'a>, String> {
        if self.head.seq > MAX_SEQ {
            return Err(format!(
                "a sample numbered {} (at most {MAX_SEQ})",
                self.head.seq
            ));
        }
        Ok(self)
    }

    /// Publish this sample into the local copy `topic` of its topic, as its publisher did.
    /// `offset` (the publisher's `seq` minus the copy's, kept by the caller per topic, `None`
    /// before the first sample) lets a subscriber join late: what was published before its
    /// first sample is not its loss. After that, a gap in `seq` is counted as lost on the wire
    /// ([`ratelab_core::topic::Subscription::count_lost`]) before the sample is published. A publisher that
    /// restarted (its `seq` went back) is taken as a new one. A `seq` more than
    /// [`MAX_SEQ_JUMP`] ahead of the last is refused, not counted as lost: no publisher gets
    /// that far ahead of its subscriber in a run, and a forged number must not inflate `lost`.
    ///
    /// `arrived`, the buffer the sample (or, in pieces, its frame) was read from when it can
    /// be shared (a shared-memory buffer's), lets the message's pixels be a view of it rather
    /// than a copy ([`ratelab_core::pixels::decode_within`]); `None` copies them.
    ///
    /// # Errors
    /// The payload's type is not the topic's (a graph that differs between processes), or its
    /// `seq` jumps too far ahead (nothing is published or counted).
    pub fn deliver(
        &self,
        topic: &AnyTopic,
        offset: &mut Option<i128>,
        arrived: Option<&bytes::Bytes>,
    ) -> Result<(), String> {
        let head = self.head;
        let stamp = Nanos(head.stamp_ns);
        let origin = head.origin_ns.map(Nanos);
        let seq = i128::from(head.seq);
        let decode = || self.data.decode(topic.msg_type());
        let data = match arrived {
            Some(buffer) => ratelab_core::pixels::decode_within(buffer, decode),
            None => decode(),
        }
        .map_err(|e| format!("a sample on {}: {e}", topic.name()))?;
        let next = i128::from(topic.next_seq());
        let off = match *offset {
            Some(off) if seq - off >= next - 1 => off,
            _ => seq - next, // the first sample, or a restarted publisher
        };
        let gap = u64::try_from(seq - off - next).unwrap_or(0);
        if gap > MAX_SEQ_JUMP {
            return Err(format!(
                "a sample numbered {gap} ahead of the last (at most {MAX_SEQ_JUMP})"
            ));
        }
        *offset = Some(off);
        if gap > 0 {
            topic.count_lost(gap);
        }
        topic.publish(None, &data, stamp, origin)
    }
}

impl WireSample {
    /// Publish this sample into the local copy `topic` of its topic: [`SampleView::deliver`]
    /// of its view, the pixels copied.
    ///
    /// # Errors
    /// As [`SampleView::deliver`].
    pub fn deliver(self, topic: &AnyTopic, offset: &mut Option<i128>) -> Result<(), String> {
        self.view().deliver(topic, offset, None)
    }

    /// This sample read in place.
    pub fn view(&self) -> SampleView<'_> {
        SampleView {
            head: self.head,
            data: Payload::One(&self.data),
        }
    }

    /// Encode (postcard).
    pub fn encode(&self) -> Vec<u8> {
        postcard::to_allocvec(self).unwrap_or_default()
    }

    /// Decode, owning the payload: [`SampleView::decode`], its payload copied.
    ///
    /// # Errors
    /// One line.
    pub fn decode(bytes: &[u8]) -> Result<WireSample, String> {
        let view = SampleView::decode(bytes)?;
        Ok(WireSample {
            head: view.head,
            data: view.data.to_vec(),
        })
    }
}

/// Virtual clock: one event done (a tick started, or its outputs gone out), from its node's
/// process to the launcher (key `ratelab/<graph>/@ticked/<process>`, in a message with the
/// reports of the process's events just before it, [`encode_reports`]), which hands it to
/// every other process ([`crate::lockstep`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ticked {
    /// The node's process.
    pub process: String,
    /// The event's place in the run's one order of events (0, 1, …: the virtual
    /// scheduler's order, [`ratelab_runtime::runcore::RunCore::next_event`], which every
    /// process computes alike).
    pub index: u64,
    /// The node (index in the graph).
    pub node: usize,
    /// Run time of the tick, ns.
    pub t_ns: u64,
    /// The node stopped the graph (the fall).
    pub stop: bool,
    /// What the node sent to other processes in the tick: (topic index, seq) per topic it
    /// sent a message on, in the node's `publishes` order.
    pub published: Vec<(usize, u64)>,
    /// The node panicked (or its input never came): the message.
    pub failed: Option<String>,
    /// The event is the end of the tick's compute time (its held outputs went out then,
    /// [`ratelab_runtime::scheduler::Event::Publish`]), not its start. Only under executors or compute
    /// times ([`ratelab_core::executor`]).
    pub publish: bool,
    /// At a start: the tick's compute time as the node drew it, ns (0: its outputs went out
    /// at once). Every other process schedules the tick's end by it
    /// ([`ratelab_runtime::scheduler::VirtualScheduler::start_elsewhere`]); at most
    /// [`ratelab_core::executor::MAX_COMPUTE`].
    pub compute_ns: u64,
}

/// The most messages a process sends on one crossing topic for one tick of its publisher
/// (a node may publish several times in a tick); past it the rest of that tick's are not
/// sent, and the subscriber counts them lost on the wire when a later one arrives. Reports
/// are checked against it ([`crate::launcher::check_report`]).
pub const MAX_SENT_PER_TICK: usize = 256;

/// The room for one tick report in a message of them, bytes: a message is read up to
/// [`MAX_TICKS_PER_MESSAGE`] times this ([`decode_reports`]; a report is about 30 bytes, and
/// its sender cuts a failure's text to 2 000 characters).
pub const MAX_TICK_BYTES: usize = 8 * 1024;

/// The most tick reports one message carries: a process sends the reports of its
/// consecutive events together when it must next wait, or once this many are waiting
/// ([`encode_reports`]).
pub const MAX_TICKS_PER_MESSAGE: usize = 64;

/// Encode a process's reports of consecutive events, oldest first, as one message
/// (postcard: the lockstep's traffic takes serde's compact binary form, as samples do, not
/// JSON). One message a hop, not one an event: an instant of the chapter's graph costs the
/// robot's process one report message (its actuator's and sensor's events) and the
/// policy's one, beside the two samples.
pub fn encode_reports(reports: &[Ticked]) -> Vec<u8> {
    postcard::to_allocvec(reports).unwrap_or_default()
}

/// Decode a message of tick reports, refusing it whole when it is over
/// [`MAX_TICKS_PER_MESSAGE`] × [`MAX_TICK_BYTES`] bytes, holds more than
/// [`MAX_TICKS_PER_MESSAGE`] reports or none, or is malformed (it must decode exactly, no
/// byte after its end); its text arrives printable ([`printable`](ratelab_core::text::printable)).
///
/// # Errors
/// One line.
pub fn decode_reports(bytes: &[u8]) -> Result<Vec<Ticked>, String> {
    decode_report_list(bytes, MAX_TICKS_PER_MESSAGE)
}

/// Decode a message of 1 to `most` tick reports (at most `most` × [`MAX_TICK_BYTES`] bytes),
/// exactly, their text made printable: [`decode_reports`], and the launcher's relayed ones
/// (`super::decode_relayed`).
///
/// # Errors
/// One line.
pub(super) fn decode_report_list(bytes: &[u8], most: usize) -> Result<Vec<Ticked>, String> {
    let max = most.saturating_mul(MAX_TICK_BYTES);
    let mut ts: Vec<Ticked> = decode_exact(bytes, max, "message of tick reports")?;
    if ts.is_empty() || ts.len() > most {
        return Err(format!(
            "a message of {} tick reports (1 to {most})",
            ts.len()
        ));
    }
    for t in &mut ts {
        // Replaced only where a control character was written out: a report's text is
        // printable as sent, and every process decodes every other's reports on its turn's path.
        if let std::borrow::Cow::Owned(p) = ratelab_core::text::printable(&t.process) {
            t.process = p;
        }
        if let Some(std::borrow::Cow::Owned(f)) =
            t.failed.as_deref().map(ratelab_core::text::printable)
        {
            t.failed = Some(f);
        }
    }
    Ok(ts)
}
