//! What crosses a process boundary: topic samples and the launcher's control messages.
//!
//! A topic sample is [`WireSample`]: the publisher's `seq`, publish stamp and origin stamp
//! (the same three numbers an in-process [`crate::topic::Message`] carries), the send time
//! on the host's monotonic clock (for the over-the-wire latency) and the payload, encoded
//! with `postcard` (serde's compact binary format). Control messages ([`ToMember`],
//! [`ToLauncher`]) are JSON (`serde_json`): few, and readable when debugging with
//! `z_sub`. Every decode is bounded ([`MAX_SAMPLE_BYTES`], [`MAX_CONTROL_BYTES`]): the
//! bytes come from the network.

use crate::config::ClockKind;
use crate::msg::AnyTopic;
use crate::qos::Fault;
use crate::run::GraphState;
use crate::scheduler::RunEnd;
use crate::time::Nanos;
use serde::{Deserialize, Serialize};

/// The largest topic sample accepted, bytes (a state sample is about 40).
pub const MAX_SAMPLE_BYTES: usize = 1024;
/// The largest control message accepted, bytes (a report with its counters is a few KB; a
/// graph file is at most [`crate::input`]'s bound).
pub const MAX_CONTROL_BYTES: usize = 4 << 20;

/// The largest sequence number accepted: an hour at 10 kHz is 3.6 × 10⁷ messages; this
/// leaves room and keeps every counter far from overflow.
pub const MAX_SEQ: u64 = 1 << 40;

/// The most a subscriber accepts a publisher's `seq` to move ahead of the last it received:
/// a gap up to this is counted as lost on the wire, a larger one refused
/// ([`WireSample::deliver`]). A 10 000 Hz publisher takes 100 s to publish this many.
pub const MAX_SEQ_JUMP: u64 = 1_000_000;

/// One topic sample on the wire.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireSample {
    /// The publisher's sequence number for the topic (from 0).
    pub seq: u64,
    /// Run time of the publish, ns (the graph's processes share the run's clock).
    pub stamp_ns: u64,
    /// The origin stamp (the sensor reading it derives from), ns.
    pub origin_ns: Option<u64>,
    /// When it was sent, on the host's `CLOCK_MONOTONIC`, ns: receive time minus this is
    /// the over-the-wire latency (exact on one host; across hosts, see docs/distributed.md).
    pub sent_mono_ns: u64,
    /// The payload: the message in its type's wire encoding ([`crate::msg::MsgData::to_bytes`]),
    /// decoded by the receiving topic's type ([`crate::msg::MsgType::decode`]), exactly.
    pub data: Vec<u8>,
}

impl WireSample {
    /// Publish this sample into the local copy `topic` of its topic, as its publisher did.
    /// `offset` (the publisher's `seq` minus the copy's, kept by the caller per topic, `None`
    /// before the first sample) lets a subscriber join late: what was published before its
    /// first sample is not its loss. After that, a gap in `seq` is counted as lost on the wire
    /// ([`crate::topic::Topic::count_lost`]) before the sample is published. A publisher that
    /// restarted (its `seq` went back) is taken as a new one. A `seq` more than
    /// [`MAX_SEQ_JUMP`] ahead of the last is refused, not counted as lost: no publisher gets
    /// that far ahead of its subscriber in a run, and a forged number must not inflate `lost`.
    ///
    /// # Errors
    /// The payload's type is not the topic's (a graph that differs between processes), or its
    /// `seq` jumps too far ahead (nothing is published or counted).
    pub fn deliver(self, topic: &AnyTopic, offset: &mut Option<i128>) -> Result<(), String> {
        let stamp = Nanos(self.stamp_ns);
        let origin = self.origin_ns.map(Nanos);
        let seq = i128::from(self.seq);
        let data = topic
            .msg_type()
            .decode(&self.data)
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

    /// Encode (postcard).
    pub fn encode(&self) -> Vec<u8> {
        postcard::to_allocvec(self).unwrap_or_default()
    }

    /// Decode, refusing anything over [`MAX_SAMPLE_BYTES`] or malformed: it must decode
    /// exactly (no byte after its end), and a `seq` beyond [`MAX_SEQ`] is refused too (no run
    /// publishes that many, and counters must not overflow).
    ///
    /// # Errors
    /// One line.
    pub fn decode(bytes: &[u8]) -> Result<WireSample, String> {
        let s: WireSample = decode_exact(bytes, MAX_SAMPLE_BYTES, "sample")?;
        if s.seq > MAX_SEQ {
            return Err(format!("a sample numbered {} (at most {MAX_SEQ})", s.seq));
        }
        Ok(s)
    }
}

/// The host's `CLOCK_MONOTONIC`, ns: the clock every process on one host shares (Rust's
/// `Instant` reads the same clock on Linux).
pub fn mono_now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; the clock id is a constant.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    if rc != 0 {
        return 0;
    }
    (ts.tv_sec as u64).saturating_mul(1_000_000_000) + ts.tv_nsec as u64
}

/// The `Instant` at `CLOCK_MONOTONIC` reading `mono_ns` (past or future).
pub fn instant_at_mono(mono_ns: u64) -> std::time::Instant {
    let (now_mono, now) = (mono_now_ns(), std::time::Instant::now());
    if mono_ns >= now_mono {
        now + std::time::Duration::from_nanos(mono_ns - now_mono)
    } else {
        now.checked_sub(std::time::Duration::from_nanos(now_mono - mono_ns))
            .unwrap_or(now)
    }
}

/// What a placement group needs to run its part of the graph: the launcher's settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Setup {
    /// The resolved graph (every override applied), as a graph file.
    pub graph_toml: String,
    /// Reset seed.
    pub seed: u64,
    /// Run length, ns.
    pub duration_ns: u64,
    /// Which clock.
    pub clock: ClockKind,
    /// The brain spec (`--policy`).
    pub policy: String,
    /// Faults to inject.
    pub faults: Vec<Fault>,
    /// Each node's first deadline, ns.
    pub phase_offsets_ns: Vec<u64>,
    /// Real clock: the spin margin, ns.
    pub spin_margin_ns: u64,
    /// Real clock: `SCHED_FIFO` priority.
    pub rt_priority: Option<u8>,
    /// `--ros2`: the ROS 2 domain each process offers its own nodes on
    /// ([`crate::ros2::bridge::Offer::local`]); `None`: not offered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2_domain: Option<u32>,
}

impl Setup {
    /// The run these settings describe: the graph parsed from [`Setup::graph_toml`], with
    /// every other setting, validated.
    ///
    /// # Errors
    /// [`super::DistError::Usage`] naming what is wrong (the bytes came from the network).
    pub fn run_config(&self) -> Result<crate::config::RunConfig, super::DistError> {
        let spec = crate::graph::spec::GraphSpec::parse(&self.graph_toml, "the launcher's graph")
            .map_err(|e| super::DistError::Usage(e.to_string()))?;
        let cfg = crate::config::RunConfig {
            seed: self.seed,
            duration: Nanos(self.duration_ns),
            graph: spec,
            clock: self.clock,
            spin_margin: Nanos(self.spin_margin_ns),
            phase_offsets: self.phase_offsets_ns.iter().copied().map(Nanos).collect(),
            rt_priority: self.rt_priority,
            faults: self.faults.clone(),
        };
        cfg.validate()
            .map_err(|e| super::DistError::Usage(format!("the launcher's settings: {e}")))?;
        Ok(cfg)
    }
}

/// The launcher's word that the run is over (key `ratelab/<graph>/@ended`): the merged
/// summary, as `launch` prints it, for whoever watches (`ratelab lab --attach`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunOver {
    /// The merged metrics.
    pub metrics: crate::metrics::Metrics,
    /// How the run ended.
    pub end: RunEnd,
}

/// The over-the-wire latency of one topic into one process: from the publisher's send to
/// the subscriber's delivery, on the host's monotonic clock (exact on one host).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireLink {
    /// The topic.
    pub topic: String,
    /// The receiving process.
    pub process: String,
    /// Samples received.
    pub samples: u64,
    /// Latency p50, µs.
    pub p50_us: f64,
    /// Latency p99, µs.
    pub p99_us: f64,
    /// Latency max, µs.
    pub max_us: f64,
    /// Set by the launcher when the receiving process rejoined mid-run: the run time of its
    /// rejoin, ns. Its figures count from then (the process before it took its own with it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub since_ns: Option<u64>,
}

/// Launcher → one placement group (key `ratelab/<graph>/@ctl/<process>`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "msg", rename_all = "snake_case")]
pub enum ToMember {
    /// Joined: here are the settings.
    Welcome {
        /// The settings.
        setup: Box<Setup>,
        /// The launcher's `CLOCK_MONOTONIC` when it sent this, ns: a real-clock run needs
        /// one host's clock (a member compares it with its own).
        launcher_mono_ns: u64,
    },
    /// Not joined, and why (one line).
    Reject {
        /// Why.
        reason: String,
        /// A process of that name is still running in the graph (as far as the launcher
        /// knows: a process killed a moment ago until its liveliness token is withdrawn). A
        /// process started again at once asks again for a while
        /// ([`super::member::BUSY_RETRY`]).
        #[serde(default)]
        busy: bool,
    },
    /// Real clock: start; run time zero is at this `CLOCK_MONOTONIC` reading, ns.
    Start {
        /// Run time zero.
        start_mono_ns: u64,
    },
    /// Virtual clock: run every tick due at or before run time `until_ns` (the lockstep's
    /// horizon, [`super::lockstep`]). The launcher moves it on ahead of the ticks it has
    /// seen done, and stops moving it to end the run early (an interrupt).
    Horizon {
        /// Run time, ns.
        until_ns: u64,
    },
    /// The run ended at run time `at_ns`: once the local copies of the input topics hold
    /// the messages `need` (topic index, seq: the last its publisher sent; virtual clock),
    /// report and leave.
    Stop {
        /// Run time of the end, ns.
        at_ns: u64,
        /// Messages still to arrive before the report.
        #[serde(default)]
        need: Vec<(usize, u64)>,
    },
}

/// A placement group → the launcher (key `ratelab/<graph>/@up`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "msg", rename_all = "snake_case")]
pub enum ToLauncher {
    /// Asks to join, with the SHA-256 of its graph file (hex).
    Join {
        /// Its process name.
        process: String,
        /// SHA-256 of the graph file it was given, hex.
        graph_sha256: String,
        /// Its OS process id.
        pid: u32,
    },
    /// Built, connected, every outbound topic matched: ready to run.
    Ready {
        /// Its process name.
        process: String,
    },
    /// Real clock: its part of the graph ended on its own (a fall, a failed node, the
    /// duration).
    Ended {
        /// Its process name.
        process: String,
        /// How.
        end: RunEnd,
    },
    /// Its state at the end of the run.
    Report {
        /// Its process name.
        process: String,
        /// Its view of the graph.
        state: Box<GraphState>,
        /// The over-the-wire latency of each topic it received from another process.
        wire: Vec<WireLink>,
    },
}

impl ToLauncher {
    /// The sender's process name.
    pub fn process(&self) -> &str {
        match self {
            ToLauncher::Join { process, .. }
            | ToLauncher::Ready { process }
            | ToLauncher::Ended { process, .. }
            | ToLauncher::Report { process, .. } => process,
        }
    }
}

/// Virtual clock: one event done (a tick started, or its outputs gone out), from its node's process to every other process and the
/// launcher (key `ratelab/<graph>/@ticked/<process>`, [`super::lockstep`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ticked {
    /// The node's process.
    pub process: String,
    /// The event's place in the run's one order of events (0, 1, …: the virtual
    /// scheduler's order, [`crate::scheduler::VirtualScheduler::next_event_until`], which every
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
    /// [`crate::scheduler::Event::Publish`]), not its start. Only under executors or compute
    /// times ([`crate::executor`]).
    pub publish: bool,
    /// At a start: the tick's compute time as the node drew it, ns (0: its outputs went out
    /// at once). Every other process schedules the tick's end by it
    /// ([`crate::scheduler::VirtualScheduler::start_elsewhere`]); at most
    /// [`crate::executor::MAX_COMPUTE`].
    pub compute_ns: u64,
}

/// Decode `bytes` (postcard) as a `T`, exactly: refused over `max` bytes, malformed, or
/// with any byte after its end; `what` names it in the one-line error.
fn decode_exact<T: for<'de> Deserialize<'de>>(
    bytes: &[u8],
    max: usize,
    what: &str,
) -> Result<T, String> {
    if bytes.len() > max {
        return Err(format!("a {what} of {} bytes (at most {max})", bytes.len()));
    }
    let (t, rest): (T, &[u8]) =
        postcard::take_from_bytes(bytes).map_err(|e| format!("a malformed {what}: {e}"))?;
    if !rest.is_empty() {
        return Err(format!(
            "a malformed {what}: {} bytes after its end",
            rest.len()
        ));
    }
    Ok(t)
}

/// The most messages a process sends on one crossing topic for one tick of its publisher
/// (a node may publish several times in a tick); past it the rest of that tick's are not
/// sent, and the subscriber counts them lost on the wire when a later one arrives. Reports
/// are checked against it ([`super::launcher::check_report`]).
pub const MAX_SENT_PER_TICK: usize = 256;

/// The largest tick report read, bytes ([`Ticked::decode`]).
pub const MAX_TICK_BYTES: usize = 8 * 1024;

impl Ticked {
    /// Encode (postcard: tick reports are the lockstep's traffic, one per tick, so they
    /// take serde's compact binary form, as samples do, not JSON).
    pub fn encode(&self) -> Vec<u8> {
        postcard::to_allocvec(self).unwrap_or_default()
    }

    /// Decode, refusing anything over [`MAX_TICK_BYTES`] or malformed (it must decode
    /// exactly, no byte after its end); its text arrives printable ([`printable`]).
    ///
    /// # Errors
    /// One line.
    pub fn decode(bytes: &[u8]) -> Result<Ticked, String> {
        let mut t: Ticked = decode_exact(bytes, MAX_TICK_BYTES, "tick report")?;
        t.process = printable(&t.process);
        t.failed = t.failed.as_deref().map(printable);
        Ok(t)
    }
}

/// Encode a control message (JSON).
pub fn encode_json<T: Serialize>(msg: &T) -> Vec<u8> {
    serde_json::to_vec(msg).unwrap_or_default()
}

/// Decode a control message, refusing anything over [`MAX_CONTROL_BYTES`] or malformed.
/// Its text arrives printable: every control character in any string or map key (an escape
/// sequence that would clear a terminal, a C1 control, DEL) is written out as `\u{1b}`
/// ([`printable`]) before anything prints or records it. The one exception is a [`Setup`]'s
/// `graph_toml`, a file's text with its newlines, which is parsed and validated
/// ([`crate::graph::GraphSpec::parse`]), never printed.
///
/// # Errors
/// One line.
pub fn decode_json<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<T, String> {
    if bytes.len() > MAX_CONTROL_BYTES {
        return Err(format!(
            "a control message of {} bytes (at most {MAX_CONTROL_BYTES})",
            bytes.len()
        ));
    }
    let malformed = |e: serde_json::Error| format!("a malformed control message: {e}");
    if !may_hold_control(bytes) {
        // JSON strings hold a control character only escaped (`\u001b`, `\n`) or, for DEL
        // and the C1 controls, raw: with neither, decode as it is (the lockstep's path).
        return serde_json::from_slice(bytes).map_err(malformed);
    }
    let mut value: serde_json::Value = serde_json::from_slice(bytes).map_err(malformed)?;
    make_printable(&mut value);
    serde_json::from_value(value).map_err(malformed)
}

/// Could `json` hold a control character in a string: a `\` escape, a raw DEL, or a raw C1
/// control (UTF-8 `C2 80`–`C2 9F`)?
fn may_hold_control(json: &[u8]) -> bool {
    json.iter().any(|&b| b == b'\\' || b == 0x7f)
        || json
            .windows(2)
            .any(|w| w[0] == 0xc2 && (0x80..=0x9f).contains(&w[1]))
}

fn make_printable(v: &mut serde_json::Value) {
    use serde_json::Value;
    match v {
        Value::String(s) if s.chars().any(char::is_control) => *s = printable(s),
        Value::Array(a) => a.iter_mut().for_each(make_printable),
        Value::Object(o) => {
            let entries = std::mem::take(o);
            for (k, mut x) in entries {
                if k != "graph_toml" {
                    make_printable(&mut x);
                }
                o.insert(printable(&k), x);
            }
        }
        _ => {}
    }
}

/// `text` with every control character written out (`\u{1b}`, `\n`): what a terminal,
/// `top` and a recording may show of text from the network.
pub fn printable(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{ForceMsg, Message, MsgData, PositionMsg};

    #[test]
    fn a_sample_round_trips_and_hostile_bytes_are_refused() {
        let s = WireSample {
            seq: 7,
            stamp_ns: 20_000_000,
            origin_ns: Some(0),
            sent_mono_ns: 5,
            data: MsgData::new([0.1f32, -0.2, 1.0, 0.0, 3.5]).to_bytes(),
        };
        assert_eq!(WireSample::decode(&s.encode()).unwrap(), s);
        assert!(WireSample::decode(&[0xff; 3]).is_err());
        assert!(WireSample::decode(&vec![0; MAX_SAMPLE_BYTES + 1]).is_err());
        let huge = WireSample {
            seq: u64::MAX,
            ..s.clone()
        };
        assert!(WireSample::decode(&huge.encode()).is_err());
        // Exactly: a valid sample with a byte after it, or a run of zeros (which starts like
        // a sample numbered 0), is refused.
        let mut longer = s.encode();
        longer.push(0);
        let e = WireSample::decode(&longer).unwrap_err();
        assert!(e.contains("1 bytes after its end"), "{e}");
        assert!(WireSample::decode(&[0u8; 1024]).is_err());
        assert!(decode_json::<ToMember>(b"{\"msg\":\"nope\"}").is_err());
    }

    #[test]
    fn text_from_the_network_arrives_printable() {
        // An escape sequence that clears the screen, a newline, a raw C1 CSI and DEL.
        let bytes = "{\"msg\":\"ready\",\"process\":\"a\\u001b[2J\\nb\u{9b}c\u{7f}\"}".as_bytes();
        let m = decode_json::<ToLauncher>(bytes).unwrap();
        assert_eq!(m.process(), "a\\u{1b}[2J\\nb\\u{9b}c\\u{7f}");
        assert!(!m.process().chars().any(char::is_control));
        // Map keys too (a report's per-node tables are keyed by name).
        let mut v = serde_json::json!({"n\u{1b}": ["x\u{7}"]});
        make_printable(&mut v);
        assert_eq!(v, serde_json::json!({"n\\u{1b}": ["x\\u{7}"]}));
        // Plain text and escapes that are not controls pass unchanged.
        let plain =
            decode_json::<ToLauncher>(r#"{"msg":"ready","process":"robot \"1\" é"}"#.as_bytes())
                .unwrap();
        assert_eq!(plain.process(), "robot \"1\" é");
        assert_eq!(printable("50 Hz · ok"), "50 Hz · ok");
        // A graph file's text keeps its lines (it is parsed, not printed).
        let setup = Setup {
            graph_toml: crate::graph::GraphSpec::chapter().to_toml(),
            seed: 0,
            duration_ns: 1,
            clock: ClockKind::Virtual,
            policy: "scripted\u{1b}".into(),
            faults: Vec::new(),
            phase_offsets_ns: Vec::new(),
            rt_priority: None,
            spin_margin_ns: 0,
            ros2_domain: None,
        };
        let bytes = serde_json::to_vec(&setup).unwrap();
        let back = decode_json::<Setup>(&bytes).unwrap();
        assert_eq!(back.graph_toml, setup.graph_toml);
        assert_eq!(back.policy, "scripted\\u{1b}");
    }

    #[test]
    fn delivery_keeps_the_publishers_numbering_and_counts_gaps_as_lost() {
        let t = AnyTopic::new("/action", ForceMsg::TYPE, 1).unwrap();
        let sample = |seq| WireSample {
            seq,
            stamp_ns: seq * 20_000_000,
            origin_ns: None,
            sent_mono_ns: 0,
            data: MsgData::new(ForceMsg { newtons: 1.0 }).to_bytes(),
        };
        let mut off = None;
        sample(0).deliver(&t, &mut off).unwrap();
        sample(3).deliver(&t, &mut off).unwrap(); // 1 and 2 never arrived
        let st = t.stats();
        assert_eq!((st.published, st.lost, st.dropped), (4, 2, 1));
        let f = t.typed::<ForceMsg>().unwrap();
        assert_eq!(f.peek_newest().unwrap().seq, 3);
        let wrong = WireSample {
            data: MsgData::new(PositionMsg {
                cart_pos_m: 0.0,
                pole_angle_rad: 0.0,
            })
            .to_bytes(),
            ..sample(4)
        };
        assert!(wrong.deliver(&t, &mut off).is_err());
        // A publisher that restarted counts from 0 again: a new numbering, nothing lost.
        sample(0).deliver(&t, &mut off).unwrap();
        sample(1).deliver(&t, &mut off).unwrap();
        assert_eq!(t.stats().lost, 2);
        assert_eq!(t.stats().published, 6);
        // A number far ahead is refused: nothing published, nothing counted lost, and the
        // numbering goes on from the last one accepted.
        let e = sample(1 + MAX_SEQ_JUMP + 2)
            .deliver(&t, &mut off)
            .unwrap_err();
        assert!(e.contains("ahead of the last"), "{e}");
        assert_eq!((t.stats().lost, t.stats().published), (2, 6));
        sample(1 + MAX_SEQ_JUMP + 1).deliver(&t, &mut off).unwrap();
        assert_eq!(t.stats().lost, 2 + MAX_SEQ_JUMP);
        sample(2 + MAX_SEQ_JUMP).deliver(&t, &mut off).unwrap();
        assert_eq!(t.stats().lost, 2 + MAX_SEQ_JUMP);
    }

    #[test]
    fn a_late_subscriber_does_not_count_what_came_before_it_as_lost() {
        let t = AnyTopic::new("/obs", ForceMsg::TYPE, 1).unwrap();
        let mut off = None;
        for seq in [100, 101, 103] {
            WireSample {
                seq,
                stamp_ns: seq,
                origin_ns: None,
                sent_mono_ns: 0,
                data: MsgData::new(ForceMsg { newtons: 0.0 }).to_bytes(),
            }
            .deliver(&t, &mut off)
            .unwrap();
        }
        let st = t.stats();
        assert_eq!((st.published, st.lost), (4, 1));
    }
}
