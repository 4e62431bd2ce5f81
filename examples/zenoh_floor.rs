//! The transport's floor on this host, for BENCHMARKS.md (issues 13 and 27): what one message
//! costs through bare Zenoh, opened with ratelab's own session config (mutual TLS and the
//! graph's access control, [`ratelab::distributed::open_session`]) and runtime threads
//! ([`ratelab::distributed::ZENOH_RUNTIME`]), through Zenoh on plain TCP without
//! authentication (what ratelab used before issue 27), and through a bare TCP socket, with
//! nothing of ratelab's on the path. `scripts/bench-distributed.sh` runs it in
//! the same sitting as ratelab's own figures, so the two can be read as a ratio.
//!
//! ```sh
//! target/release/examples/zenoh_floor            # every measure, about 30 s
//! ```
//!
//! It starts one copy of itself as the far process (`--far TRANSPORT ENDPOINT CREDENTIALS`)
//! and measures,
//! per transport:
//! - **one way at 50 Hz and at 1 kHz**: from the send to the far side's receive callback, on
//!   the host's `CLOCK_MONOTONIC` (as ratelab's "wire" latency is measured), 500 and 5000
//!   messages;
//! - **round trips back to back** (5000): the far side hands each message from its receive
//!   callback to a thread that sends it back, as a lockstep process hands a tick report to
//!   the node thread that then ticks and reports. A lockstep instant of the chapter's graph is
//!   two such one-way hops, so the mean round trip is the floor of its wall time per instant.

use hdrhistogram::Histogram;
use ratelab::distributed::credentials::{Credentials, Role};
use ratelab::distributed::wire::mono_now_ns;
use ratelab::distributed::{open_session, zenoh, zenoh::Wait, Access};
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// One message: [kind (0 = one way, 1 = echo, 2 = end), pad, send stamp ns, receive stamp ns].
const MSG_BYTES: usize = 24;

fn encode(kind: u8, sent_ns: u64, received_ns: u64) -> [u8; MSG_BYTES] {
    let mut b = [0u8; MSG_BYTES];
    b[0] = kind;
    b[8..16].copy_from_slice(&sent_ns.to_le_bytes());
    b[16..24].copy_from_slice(&received_ns.to_le_bytes());
    b
}

fn decode(b: &[u8]) -> Option<(u8, u64, u64)> {
    let b: &[u8; MSG_BYTES] = b.try_into().ok()?;
    let word = |r: std::ops::Range<usize>| u64::from_le_bytes(b[r].try_into().unwrap_or([0; 8]));
    Some((b[0], word(8..16), word(16..24)))
}

/// A link to the far process: send one message, wait for the next one back.
trait Link {
    fn send(&mut self, msg: [u8; MSG_BYTES]);
    fn recv(&mut self) -> [u8; MSG_BYTES];
}

struct ZenohLink {
    _session: ratelab::distributed::zenoh::Session,
    publisher: ratelab::distributed::zenoh::pubsub::Publisher<'static>,
    _subscriber: ratelab::distributed::zenoh::pubsub::Subscriber<()>,
    back: crossbeam_channel::Receiver<[u8; MSG_BYTES]>,
}

impl Link for ZenohLink {
    fn send(&mut self, msg: [u8; MSG_BYTES]) {
        self.publisher.put(msg.to_vec()).wait().expect("a put");
    }
    fn recv(&mut self) -> [u8; MSG_BYTES] {
        self.back
            .recv_timeout(Duration::from_secs(10))
            .expect("the far side answers within 10 s")
    }
}

struct TcpLink(std::net::TcpStream);

impl Link for TcpLink {
    fn send(&mut self, msg: [u8; MSG_BYTES]) {
        self.0.write_all(&msg).expect("a write");
    }
    fn recv(&mut self) -> [u8; MSG_BYTES] {
        let mut b = [0u8; MSG_BYTES];
        self.0.read_exact(&mut b).expect("a read");
        b
    }
}

/// Subscribe `key` on `session`; every message goes to `f` inside Zenoh's receive callback.
fn subscribe(
    session: &ratelab::distributed::zenoh::Session,
    key: &'static str,
    f: impl Fn([u8; MSG_BYTES]) + Send + Sync + 'static,
) -> ratelab::distributed::zenoh::pubsub::Subscriber<()> {
    session
        .declare_subscriber(key)
        .callback(move |s| {
            if let Some(m) = decode(&s.payload().to_bytes()).map(|(k, a, b)| encode(k, a, b)) {
                f(m)
            }
        })
        .wait()
        .expect("a subscriber")
}

/// A Zenoh session for `transport`: `zenoh-tls` is ratelab's own (as process `who` of
/// graph `floor`, with the credentials at `creds`), `zenoh-tcp` the same peer-mode settings
/// on plain TCP with no authentication and no access control.
fn session(
    transport: &str,
    listen: &[String],
    connect: &[String],
    creds: &str,
    who: &str,
) -> zenoh::Session {
    if transport == "zenoh-tls" {
        let credentials = Credentials::load(std::path::Path::new(creds)).expect("credentials");
        let access = Access {
            credentials: &credentials,
            role: &Role::Process(who.into()),
            spec: None,
        };
        return open_session(listen, connect, access).expect("a session");
    }
    let mut c = zenoh::Config::default();
    let json = |v: &[String]| serde_json::to_string(v).expect("JSON");
    for (k, v) in [
        ("mode", "\"peer\"".to_string()),
        ("scouting/multicast/enabled", "false".into()),
        ("listen/endpoints", json(listen)),
        ("connect/endpoints", json(connect)),
    ] {
        c.insert_json5(k, &v).expect("a config");
    }
    zenoh::open(c).wait().expect("a session")
}

/// The far process: stamp each message on arrival; send echoes back from a thread, and a
/// one-way message's receive stamp back too (so the near side learns the one-way time).
fn far(transport: &str, endpoint: &str, creds: &str) {
    match transport {
        "zenoh-tls" | "zenoh-tcp" => {
            let session = session(transport, &[endpoint.to_string()], &[], creds, "far");
            let publisher = session
                .declare_publisher("ratelab/floor/back")
                .wait()
                .expect("a pub");
            let (tx, rx) = crossbeam_channel::bounded(1024);
            let _sub = subscribe(&session, "ratelab/floor/out", move |m| {
                let received = mono_now_ns();
                let _ = tx.try_send((m, received));
            });
            println!("ready");
            while let Ok((m, received)) = rx.recv() {
                let (kind, sent, _) = decode(&m).unwrap_or((2, 0, 0));
                publisher
                    .put(encode(kind, sent, received).to_vec())
                    .wait()
                    .ok();
                if kind == 2 {
                    break;
                }
            }
        }
        _ => {
            let listener = std::net::TcpListener::bind(endpoint).expect("a listener");
            println!("ready");
            let (mut s, _) = listener.accept().expect("a connection");
            s.set_nodelay(true).ok();
            let mut b = [0u8; MSG_BYTES];
            while s.read_exact(&mut b).is_ok() {
                let received = mono_now_ns();
                let (kind, sent, _) = decode(&b).unwrap_or((2, 0, 0));
                s.write_all(&encode(kind, sent, received)).ok();
                if kind == 2 {
                    break;
                }
            }
        }
    }
}

fn hist() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 10_000_000_000, 3).expect("valid bounds")
}

fn us(ns: u64) -> f64 {
    ns as f64 / 1e3
}

/// One way at `rate_hz`: `n` messages, paced on an absolute schedule.
fn one_way(link: &mut dyn Link, label: &str, rate_hz: u64, n: u64) {
    let period = Duration::from_nanos(1_000_000_000 / rate_hz);
    let (mut h, start) = (hist(), Instant::now());
    for i in 0..n + 20 {
        let due = start + period * (i as u32 + 1);
        std::thread::sleep(due.saturating_duration_since(Instant::now()));
        link.send(encode(0, mono_now_ns(), 0));
        let (_, sent, received) = decode(&link.recv()).expect("a reply");
        if i >= 20 {
            h.saturating_record(received.saturating_sub(sent).max(1));
        }
    }
    println!(
        "{label}: one way at {rate_hz} Hz: {} samples, p50 {:.1} µs | p99 {:.1} µs | max {:.1} µs",
        h.len(),
        us(h.value_at_quantile(0.5)),
        us(h.value_at_quantile(0.99)),
        us(h.max())
    );
}

/// Round trips back to back: `n` of them.
fn round_trips(link: &mut dyn Link, label: &str, n: u64) {
    let mut h = hist();
    for _ in 0..20 {
        link.send(encode(1, mono_now_ns(), 0));
        link.recv();
    }
    let start = Instant::now();
    for _ in 0..n {
        let t = mono_now_ns();
        link.send(encode(1, t, 0));
        link.recv();
        h.saturating_record(mono_now_ns().saturating_sub(t).max(1));
    }
    println!(
        "{label}: {n} round trips back to back: mean {:.1} µs (wall {:.1} µs each) | p50 {:.1} µs | p99 {:.1} µs",
        h.mean() / 1e3,
        start.elapsed().as_secs_f64() * 1e6 / n as f64,
        us(h.value_at_quantile(0.5)),
        us(h.value_at_quantile(0.99))
    );
}

fn free_port() -> u16 {
    std::net::TcpListener::bind(("127.0.0.1", 0))
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn main() {
    // ratelab's runtime threads, as `ratelab` itself sets them.
    ratelab::distributed::set_zenoh_runtime().expect("a usable ZENOH_RUNTIME");
    let args: Vec<String> = std::env::args().collect();
    if let [_, flag, transport, endpoint, creds] = args.as_slice() {
        if flag == "--far" {
            return far(transport, endpoint, creds);
        }
    }
    if args.len() != 1 {
        eprintln!("usage: zenoh_floor   (no arguments: it starts its far side itself)");
        std::process::exit(2);
    }
    let private = ratelab::distributed::credentials::PrivateDir::new().expect("a folder");
    let creds =
        Credentials::generate("floor", &["near".into(), "far".into()]).expect("credentials");
    let creds = private.write("floor", &creds).expect("written");
    let creds = creds.to_string_lossy().into_owned();
    for transport in ["zenoh-tls", "zenoh-tcp", "tcp"] {
        let addr = format!("127.0.0.1:{}", free_port());
        let endpoint = match transport {
            "zenoh-tls" => format!("tls/{addr}"),
            "zenoh-tcp" => format!("tcp/{addr}"),
            _ => addr.clone(),
        };
        let mut child = Command::new(&args[0])
            .args(["--far", transport, &endpoint, &creds])
            .stdout(Stdio::piped())
            .spawn()
            .expect("the far process starts");
        let mut ready = String::new();
        let stdout = child.stdout.take().expect("its stdout");
        BufReader::new(stdout).read_line(&mut ready).ok();
        let mut link: Box<dyn Link> = match transport {
            "zenoh-tls" | "zenoh-tcp" => {
                let session = session(
                    transport,
                    &[],
                    std::slice::from_ref(&endpoint),
                    &creds,
                    "near",
                );
                let publisher = session
                    .declare_publisher("ratelab/floor/out")
                    .wait()
                    .expect("a pub");
                let (tx, back) = crossbeam_channel::bounded(1024);
                let subscriber = subscribe(&session, "ratelab/floor/back", move |m| {
                    let _ = tx.try_send(m);
                });
                // Wait until the far side's subscriber is matched before the first put.
                while !publisher
                    .matching_status()
                    .wait()
                    .map(|m| m.matching())
                    .unwrap_or(false)
                {
                    std::thread::sleep(Duration::from_millis(10));
                }
                Box::new(ZenohLink {
                    _session: session,
                    publisher,
                    _subscriber: subscriber,
                    back,
                })
            }
            _ => {
                let s = std::net::TcpStream::connect(&addr).expect("a connection");
                s.set_nodelay(true).ok();
                Box::new(TcpLink(s))
            }
        };
        let label = match transport {
            "zenoh-tls" => "bare Zenoh (ratelab's session config: mutual TLS, access control)",
            "zenoh-tcp" => "bare Zenoh (peer mode on plain TCP, no authentication)",
            _ => "bare TCP socket (nodelay, blocking)",
        };
        one_way(link.as_mut(), label, 50, 500);
        one_way(link.as_mut(), label, 1000, 5000);
        round_trips(link.as_mut(), label, 5000);
        link.send(encode(2, 0, 0));
        let _ = child.wait();
    }
}
