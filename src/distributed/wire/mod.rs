//! What crosses a process boundary: topic samples and the launcher's control messages.
//!
//! A topic sample is [`WireSample`]: the publisher's `seq`, publish stamp and origin stamp
//! (the same three numbers an in-process [`ratelab_core::topic::Message`] carries), the send time
//! on the host's monotonic clock (for the over-the-wire latency) and the payload, encoded
//! with `postcard` (serde's compact binary format). A sample is written in place from its
//! [`SampleHead`] and the message (into a shared-memory buffer for a large one) and read in
//! place ([`SampleView`]), the same bytes as [`WireSample::encode`]. Control messages ([`ToProcess`],
//! [`ToLauncher`]) are JSON (`serde_json`): few, and readable when debugging with
//! `z_sub`. Every decode is bounded ([`MAX_SAMPLE_BYTES`], [`MAX_CONTROL_BYTES`]): the
//! bytes come from the network.

//!
//! One module per direction of travel, as dora-rs splits its messages:
//! `process_to_process` (samples and tick reports), `launcher_to_process` (control, and the
//! tick reports the launcher hands on), `process_to_launcher` and `launcher_to_watcher`;
//! the codec, its bounds and the printable text they share
//! ([`ratelab_core::text::printable`]) are here.

mod launcher_to_process;
mod launcher_to_watcher;
mod process_to_launcher;
mod process_to_process;

pub use launcher_to_process::{decode_relayed, encode_relayed, Setup, ToProcess, MAX_RELAYED};
pub use launcher_to_watcher::RunOver;
pub use process_to_launcher::{ToLauncher, WireLink};
pub use process_to_process::{
    check_sample_len, decode_reports, encode_reports, Payload, SampleHead, SampleView, Ticked,
    WireSample, MAX_SAMPLE_BYTES, MAX_SENT_PER_TICK, MAX_SEQ, MAX_SEQ_JUMP, MAX_TICKS_PER_MESSAGE,
    MAX_TICK_BYTES,
};

use serde::{Deserialize, Serialize};

pub use ratelab_core::limits::MAX_CONTROL_BYTES;

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

/// Decode `bytes` (postcard) as a `T`, exactly: refused over `max` bytes, malformed, or
/// with any byte after its end; `what` names it in the one-line error.
fn decode_exact<'a, T: Deserialize<'a>>(
    bytes: &'a [u8],
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

/// Encode a control message (JSON).
pub fn encode_json<T: Serialize>(msg: &T) -> Vec<u8> {
    serde_json::to_vec(msg).unwrap_or_default()
}

/// Decode a control message, refusing anything over [`MAX_CONTROL_BYTES`] or malformed.
/// Its text arrives printable: every control character in any string or map key (an escape
/// sequence that would clear a terminal, a C1 control, DEL) is written out as `\u{1b}`
/// ([`ratelab_core::text::printable`]) before anything prints or records it. The one exception is a [`Setup`]'s
/// `graph_toml`, a file's text with its newlines, which is parsed and validated
/// ([`ratelab_runtime::graph::GraphSpec::parse`]), never printed.
///
/// # Errors
/// One line.
pub fn decode_json<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<T, String> {
    if bytes.len() > MAX_CONTROL_BYTES {
        return Err(ratelab_core::limits::refusal(
            format_args!(
                "a control message of {} bytes (at most {MAX_CONTROL_BYTES})",
                bytes.len()
            ),
            "MAX_CONTROL_BYTES",
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
        Value::String(s) if s.chars().any(char::is_control) => {
            *s = ratelab_core::text::printable(s).into_owned()
        }
        Value::Array(a) => a.iter_mut().for_each(make_printable),
        Value::Object(o) => {
            let entries = std::mem::take(o);
            for (k, mut x) in entries {
                if k != "graph_toml" {
                    make_printable(&mut x);
                }
                o.insert(ratelab_core::text::printable(&k).into_owned(), x);
            }
        }
        _ => {}
    }
}

/// `text` cut to at most `max` bytes, on a character's boundary (text from or for the
/// network, kept within a bound).
pub fn cut_to_bytes(mut text: String, max: usize) -> String {
    if text.len() > max {
        let end = (0..=max)
            .rev()
            .find(|&k| text.is_char_boundary(k))
            .unwrap_or(0);
        text.truncate(end);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::msg::AnyTopic;
    use ratelab_core::msg::{ForceMsg, Message, MsgData, PositionMsg};
    use ratelab_runtime::config::ClockKind;

    #[test]
    fn a_sample_round_trips_and_hostile_bytes_are_refused() {
        let s = WireSample {
            head: SampleHead {
                seq: 7,
                stamp_ns: 20_000_000,
                origin_ns: Some(0),
                sent_mono_ns: 5,
            },
            data: MsgData::new([0.1f32, -0.2, 1.0, 0.0, 3.5]).to_bytes(),
        };
        assert_eq!(WireSample::decode(&s.encode()).unwrap(), s);
        assert!(WireSample::decode(&[0xff; 3]).is_err());
        assert!(WireSample::decode(&vec![0; MAX_SAMPLE_BYTES + 1]).is_err());
        let mut huge = s.clone();
        huge.head.seq = u64::MAX;
        assert!(WireSample::decode(&huge.encode()).is_err());
        // Exactly: a valid sample with a byte after it, or a run of zeros (which starts like
        // a sample numbered 0), is refused.
        let mut longer = s.encode();
        longer.push(0);
        let e = WireSample::decode(&longer).unwrap_err();
        assert!(e.contains("1 bytes after its end"), "{e}");
        assert!(WireSample::decode(&[0u8; 1024]).is_err());
        assert!(decode_json::<ToProcess>(b"{\"msg\":\"nope\"}").is_err());
        // The receipt of a report, as it travels.
        let taken = encode_json(&ToProcess::ReportTaken);
        assert_eq!(taken, br#"{"msg":"report_taken"}"#);
        assert_eq!(
            decode_json::<ToProcess>(&taken).unwrap(),
            ToProcess::ReportTaken
        );
    }

    #[test]
    fn a_sample_written_in_place_is_the_encoded_one_and_is_read_in_place() {
        let image = MsgData::new(ratelab_core::msg::ImageMsg {
            height: 300,
            width: 400,
            encoding: "mono8".into(),
            step: 400,
            data: (0..120_000u32)
                .map(|i| (i % 251) as u8)
                .collect::<Vec<_>>()
                .into(),
        });
        for (payload, origin) in [
            (image, Some(3)),
            (MsgData::new(ForceMsg { newtons: -1.5 }), None),
        ] {
            let head = SampleHead {
                seq: 300,
                stamp_ns: 1 << 40,
                origin_ns: origin,
                sent_mono_ns: u64::MAX,
            };
            let owned = WireSample {
                head,
                data: payload.to_bytes(),
            }
            .encode();
            let payload_len = payload.encoded_len();
            assert_eq!(head.sample_len(payload_len), owned.len());
            let mut out = vec![0u8; owned.len()];
            head.write(&payload, payload_len, &mut out).unwrap();
            assert_eq!(out, owned, "the same bytes as the owned sample's");
            // Too short or too long a buffer is refused before a byte is written.
            for len in [owned.len() - 1, owned.len() + 1] {
                let mut wrong = vec![7u8; len];
                assert!(head.write(&payload, payload_len, &mut wrong).is_err());
                assert!(wrong.iter().all(|&b| b == 7), "nothing written");
            }
            // Read in place: the payload is the arrived bytes themselves.
            let arrived = bytes::Bytes::from(out);
            let view = SampleView::decode(&arrived).unwrap();
            assert_eq!(view.head, head);
            let wire = payload.to_bytes();
            assert_eq!(view.data, Payload::One(&wire));
            let Payload::One(data) = view.data else {
                unreachable!("one run")
            };
            assert!(arrived.as_ptr_range().contains(&data.as_ptr()));
            // Delivered with its buffer, an image's pixels are a view of it; without, a copy.
            let t = AnyTopic::new("/t", payload.msg_type(), 2).unwrap();
            let mut off = None;
            let now = ratelab_core::time::Nanos(1 << 41);
            view.deliver(&t, &mut off, Some(&arrived)).unwrap();
            let viewed = t.read(now).expect("delivered").data;
            view.deliver(&t, &mut off, None).unwrap();
            let copied = t.read(now).expect("delivered").data;
            assert_eq!((&viewed, &copied), (&payload, &payload));
            if let Some(img) = viewed.get::<ratelab_core::msg::ImageMsg>() {
                assert!(img.data.is_within(&arrived), "a view of the arrived bytes");
                let copy = copied.get::<ratelab_core::msg::ImageMsg>().unwrap();
                assert!(!copy.data.is_within(&arrived), "a copy");
            }
        }
    }

    /// A sample in pieces (its head, then a frame in a run of its own, as a frame drawn into
    /// a lent buffer crosses) reads as the same sample in one run, its pixels a view of their
    /// run; a malformed one is refused in one line, and one whose pixels straddle two runs is
    /// still read (joined).
    #[test]
    fn a_sample_in_pieces_reads_as_in_one_run_and_a_malformed_one_is_refused() {
        let pixels: Vec<u8> = (0..70_000u32).map(|i| (i % 251) as u8).collect();
        let image = MsgData::new(ratelab_core::msg::ImageMsg {
            height: 100,
            width: 700,
            encoding: "mono8".into(),
            step: 700,
            data: pixels.clone().into(),
        });
        let head = SampleHead {
            seq: 7,
            stamp_ns: 1 << 30,
            origin_ns: Some(5),
            sent_mono_ns: 1,
        };
        let len = image.encoded_len();
        let mut one = vec![0u8; head.sample_len(len)];
        head.write(&image, len, &mut one).unwrap();
        let cut = one.len() - pixels.len();
        assert_eq!(
            &one[..head.head_bytes(len).len()],
            &head.head_bytes(len)[..]
        );
        let frame = bytes::Bytes::copy_from_slice(&one[cut..]);
        let pieces: [&[u8]; 2] = [&one[..cut], &frame];
        let view = SampleView::decode_pieces(&pieces).unwrap();
        assert_eq!(view.head, head);
        assert_eq!(view.data.to_vec(), image.to_bytes());
        let t = AnyTopic::new("/t", image.msg_type(), 1).unwrap();
        let mut off = None;
        view.deliver(&t, &mut off, Some(&frame)).unwrap();
        let got = t.read(ratelab_core::time::Nanos(1 << 41)).unwrap().data;
        assert_eq!(got, image);
        let img = got.get::<ratelab_core::msg::ImageMsg>().unwrap();
        assert!(img.data.is_within(&frame), "a view of the frame's run");
        // Pixels cut in two runs: read joined, the same message (a copy).
        let straddling: [&[u8]; 2] = [&one[..cut + 10], &one[cut + 10..]];
        let view = SampleView::decode_pieces(&straddling).unwrap();
        view.deliver(&t, &mut off, Some(&frame)).unwrap();
        let got = t.read(ratelab_core::time::Nanos(1 << 41)).unwrap().data;
        assert_eq!(got, image);
        // Refused, each in one line: no runs; a payload shorter or longer than its head
        // says; a head cut in two; a seq past the bound; a type that is not the topic's.
        assert!(SampleView::decode_pieces(&[]).is_err());
        for bad in [
            [&one[..cut], &one[cut..one.len() - 1]],
            [&one[..cut], &[&one[cut..], &[0u8][..]].concat()[..]],
            [&one[..3], &one[3..]],
        ] {
            let e = SampleView::decode_pieces(&bad).unwrap_err();
            assert!(
                e.starts_with("a malformed sample") && !e.contains('\n'),
                "{e}"
            );
        }
        let far = SampleHead {
            seq: MAX_SEQ + 1,
            ..head
        };
        let mut one_far = vec![0u8; far.sample_len(len)];
        far.write(&image, len, &mut one_far).unwrap();
        let at = one_far.len() - pixels.len();
        let e = SampleView::decode_pieces(&[&one_far[..at], &one_far[at..]]).unwrap_err();
        assert!(e.contains("numbered"), "{e}");
        let force = AnyTopic::new("/f", ForceMsg::TYPE, 1).unwrap();
        let view = SampleView::decode_pieces(&pieces).unwrap();
        let e = view.deliver(&force, &mut None, Some(&frame)).unwrap_err();
        assert!(e.contains("/f") && !e.contains('\n'), "{e}");
        assert!(check_sample_len(MAX_SAMPLE_BYTES + 1).is_err());
    }

    #[test]
    fn text_is_cut_on_a_character_s_boundary() {
        assert_eq!(cut_to_bytes("boom".into(), 10), "boom");
        assert_eq!(cut_to_bytes("boom".into(), 4), "boom");
        assert_eq!(cut_to_bytes("boom".into(), 2), "bo");
        // 'é' is two bytes: a cut inside it keeps the character before.
        assert_eq!(cut_to_bytes("aé".into(), 2), "a");
        assert_eq!(cut_to_bytes("aé".into(), 3), "aé");
        assert_eq!(cut_to_bytes("é".into(), 0), "");
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
        assert_eq!(ratelab_core::text::printable("50 Hz · ok"), "50 Hz · ok");
        // A graph file's text keeps its lines (it is parsed, not printed).
        let setup = Setup {
            graph_toml: ratelab_runtime::graph::GraphSpec::chapter().to_toml(),
            seed: 0,
            duration_ns: 1,
            clock: ClockKind::Virtual,
            policy: "scripted\u{1b}".into(),
            faults: Vec::new(),
            phase_offsets_ns: Vec::new(),
            rt_priority: None,
            spin_margin_ns: 0,
            ros2_domain: None,
            direct: true,
        };
        let bytes = serde_json::to_vec(&setup).unwrap();
        let back = decode_json::<Setup>(&bytes).unwrap();
        assert_eq!(back.graph_toml, setup.graph_toml);
        assert_eq!(back.policy, "scripted\\u{1b}");
        // A message of tick reports (postcard): its process and failure written out where
        // they hold a control character, kept as they are where not.
        let report = |process: &str, failed: Option<&str>| Ticked {
            process: process.into(),
            index: 0,
            node: 0,
            t_ns: 0,
            stop: false,
            published: Vec::new(),
            failed: failed.map(Into::into),
            publish: false,
            compute_ns: 0,
        };
        let sent = [
            report("robot\u{1b}[2J", Some("boom\n")),
            report("policy é", Some("ValueError: x")),
            report("robot", None),
        ];
        let back = decode_reports(&encode_reports(&sent)).unwrap();
        assert_eq!(back[0].process, "robot\\u{1b}[2J");
        assert_eq!(back[0].failed.as_deref(), Some("boom\\n"));
        assert_eq!(back[1..], sent[1..]);
    }

    #[test]
    fn delivery_keeps_the_publishers_numbering_and_counts_gaps_as_lost() {
        let t = AnyTopic::new("/action", ForceMsg::TYPE, 1).unwrap();
        let sample = |seq| WireSample {
            head: SampleHead {
                seq,
                stamp_ns: seq * 20_000_000,
                origin_ns: None,
                sent_mono_ns: 0,
            },
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
                head: SampleHead {
                    seq,
                    stamp_ns: seq,
                    origin_ns: None,
                    sent_mono_ns: 0,
                },
                data: MsgData::new(ForceMsg { newtons: 0.0 }).to_bytes(),
            }
            .deliver(&t, &mut off)
            .unwrap();
        }
        let st = t.stats();
        assert_eq!((st.published, st.lost), (4, 1));
    }
}
