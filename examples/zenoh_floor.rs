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
//! target/release/examples/zenoh_floor --transport zenoh-tls --round-trips 30000 --work-us 50
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
//!   It also gives the CPU time both processes spent per round trip (from `/proc`, Linux).
//!
//! Options shape the round trips like a lockstep's, to see what each part of an instant
//! costs: `--work-us N` (each side busy for N µs before it answers, as a process ticks its
//! node between two hops), `--extra-puts N` (each side puts N more messages before its
//! answer, as a hop carries a sample and its tick's report) and `--reply-in-callback` (the
//! far side answers inside Zenoh's receive callback, with no hand-off to a thread).
//! `--transport` and `--round-trips N` narrow a sitting to one transport's round trips.
//!
//! `--transport zenoh-router` measures the round trip of a launch's star (issue 76 item 2):
//! a third copy runs the launcher's Zenoh router alone (`--router ENDPOINT CREDENTIALS`, as
//! [`ratelab::distributed::open_router`] opens it: mutual TLS, access control), and both
//! sides are its clients ([`ratelab::distributed::open_client`]), so every message crosses
//! two links, as a sample and a report between two processes of a launch do. It is not
//! among the transports measured by default.

#[path = "common/floor.rs"]
mod floor;

use hdrhistogram::Histogram;
use ratelab::distributed::credentials::{Credentials, Role};
use ratelab::distributed::wire::mono_now_ns;
use ratelab::distributed::{open_client, open_router, Access};
use ratelab::distributed::{zenoh, zenoh::Wait};
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// One message: [kind (0 = one way, 1 = echo, 2 = end, 3 = filler), pad, send stamp ns,
/// receive stamp ns].
const MSG_BYTES: usize = 24;

/// Round trips per transport unless `--round-trips` says otherwise; with this number the
/// one-way measures run too (a sitting narrowed to round trips gives another).
const DEFAULT_ROUND_TRIPS: u64 = 5000;

/// A filler message (`--extra-puts`): carried, then ignored.
const FILLER: u8 = 3;

/// How the round trips are shaped (see the module's header); the far side gets the same.
#[derive(clap::Parser, Clone, Debug)]
#[command(about = "The transport's floor on this host (BENCHMARKS.md)")]
struct Opts {
    /// Only this transport: zenoh-tls, zenoh-tcp, tcp, or zenoh-router (through a router).
    #[arg(long, value_parser = ["zenoh-tls", "zenoh-tcp", "tcp", "zenoh-router"])]
    transport: Option<String>,
    /// Round trips per transport; the one-way measures run only with the default.
    #[arg(long, default_value_t = DEFAULT_ROUND_TRIPS, value_parser = clap::value_parser!(u64).range(1..=10_000_000))]
    round_trips: u64,
    /// Each side is busy this long before it answers, µs (a busy wait).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=1_000_000))]
    work_us: u64,
    /// Each side puts this many filler messages before its answer (Zenoh transports).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=100))]
    extra_puts: u32,
    /// The far side answers inside Zenoh's receive callback, not from a thread.
    #[arg(long)]
    reply_in_callback: bool,
    /// Run as the far side: TRANSPORT ENDPOINT CREDENTIALS (the near side starts it).
    #[arg(long, num_args = 3, hide = true)]
    far: Option<Vec<String>>,
    /// Run as the router of `--transport zenoh-router`: ENDPOINT CREDENTIALS (the near side
    /// starts it, and it runs until its standard input closes).
    #[arg(long, num_args = 2, hide = true)]
    router: Option<Vec<String>>,
}

impl Opts {
    /// The options the far side is started with.
    fn for_far(&self) -> Vec<String> {
        let mut v = vec![
            "--work-us".to_string(),
            self.work_us.to_string(),
            "--extra-puts".into(),
            self.extra_puts.to_string(),
        ];
        if self.reply_in_callback {
            v.push("--reply-in-callback".into());
        }
        v
    }

    /// Busy for `--work-us`.
    fn work(&self) {
        let t = Instant::now();
        while t.elapsed() < Duration::from_micros(self.work_us) {
            std::hint::spin_loop();
        }
    }
}

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
    extra_puts: u32,
    _session: ratelab::distributed::zenoh::Session,
    publisher: ratelab::distributed::zenoh::pubsub::Publisher<'static>,
    _subscriber: ratelab::distributed::zenoh::pubsub::Subscriber<()>,
    back: crossbeam_channel::Receiver<[u8; MSG_BYTES]>,
}

impl Link for ZenohLink {
    fn send(&mut self, msg: [u8; MSG_BYTES]) {
        for _ in 0..self.extra_puts {
            let filler = encode(FILLER, 0, 0).to_vec();
            self.publisher.put(filler).wait().expect("a put");
        }
        self.publisher.put(msg.to_vec()).wait().expect("a put");
    }
    fn recv(&mut self) -> [u8; MSG_BYTES] {
        loop {
            let m = self
                .back
                .recv_timeout(Duration::from_secs(10))
                .expect("the far side answers within 10 s");
            if m[0] != FILLER {
                return m;
            }
        }
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
        return floor::tls_session(listen, connect, creds, who);
    }
    if transport == "zenoh-router" {
        let endpoint = listen.first().or(connect.first()).expect("an endpoint");
        return star_session(endpoint, creds, who);
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

/// The far side's answer to message `m` received at `received` (ns): `None` for a filler;
/// else after `--work-us`, `--extra-puts` fillers and then the answer (the message's kind,
/// its send stamp and `received`). `true` at the end.
fn answer(
    opts: &Opts,
    publisher: &zenoh::pubsub::Publisher<'static>,
    m: &[u8; MSG_BYTES],
    received: u64,
) -> Option<bool> {
    let (kind, sent, _) = decode(m).unwrap_or((2, 0, 0));
    if kind == FILLER {
        return None;
    }
    opts.work();
    for _ in 0..opts.extra_puts {
        publisher.put(encode(FILLER, 0, 0).to_vec()).wait().ok();
    }
    let answer = encode(kind, sent, received).to_vec();
    publisher.put(answer).wait().ok();
    Some(kind == 2)
}

/// A Zenoh session of the launch's star, as ratelab opens its own: `who` `"router"` is a
/// router listening on `endpoint` (Zenoh's settings of the launcher's router; the identity of
/// a host's router, [`Role::HostRouter`], since the launcher's own never leaves it), any
/// other name a process that is its client (connecting to `endpoint`), with the credentials
/// at `creds`.
///
/// # Panics
/// As [`floor::tls_session`].
fn star_session(endpoint: &str, creds: &str, who: &str) -> zenoh::Session {
    let credentials = Credentials::load(std::path::Path::new(creds)).expect("credentials");
    let role = match who {
        "router" => Role::HostRouter,
        p => Role::Process(p.into()),
    };
    let access = Access {
        credentials: &credentials,
        role: &role,
        spec: None,
    };
    let at = [endpoint.to_string()];
    match role {
        Role::HostRouter => open_router(&at, access, false),
        _ => open_client(&at, access),
    }
    .expect("a session")
}

/// The far process: stamp each message on arrival; send echoes back from a thread (or, with
/// `--reply-in-callback`, from Zenoh's receive callback), and a one-way message's receive
/// stamp back too (so the near side learns the one-way time).
fn far(opts: &Opts, transport: &str, endpoint: &str, creds: &str) {
    match transport {
        "zenoh-tls" | "zenoh-tcp" | "zenoh-router" => {
            let session = session(transport, &[endpoint.to_string()], &[], creds, "far");
            let publisher = session
                .declare_publisher("ratelab/floor/back")
                .wait()
                .expect("a pub");
            let publisher = std::sync::Arc::new(publisher);
            let (tx, rx) = crossbeam_channel::bounded(1024);
            let (in_callback, o, p) = (opts.reply_in_callback, opts.clone(), publisher.clone());
            let _sub = subscribe(&session, "ratelab/floor/out", move |m| {
                let received = mono_now_ns();
                if !in_callback {
                    let _ = tx.try_send((m, received));
                } else if answer(&o, &p, &m, received) == Some(true) {
                    let _ = tx.try_send((encode(2, 0, 0), received));
                }
            });
            println!("ready");
            while let Ok((m, received)) = rx.recv() {
                if in_callback || answer(opts, &publisher, &m, received) == Some(true) {
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
                opts.work();
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

/// Round trips back to back: `n` of them, with `--work-us` before each send (the far side
/// works as long before it answers); the CPU time of this process and the far one (`far`).
fn round_trips(link: &mut dyn Link, label: &str, n: u64, opts: &Opts, far: u32) {
    let mut h = hist();
    for _ in 0..20 {
        link.send(encode(1, mono_now_ns(), 0));
        link.recv();
    }
    let start = Instant::now();
    let cpu = || Some(floor::cpu_ns(std::process::id())? + floor::cpu_ns(far)?);
    let cpu_before = cpu();
    for _ in 0..n {
        let t = mono_now_ns();
        opts.work();
        link.send(encode(1, t, 0));
        link.recv();
        h.saturating_record(mono_now_ns().saturating_sub(t).max(1));
    }
    let cpu = match (cpu_before, cpu()) {
        (Some(a), Some(b)) => format!(" | CPU {:.1} µs each", us(b.saturating_sub(a) / n)),
        _ => String::new(),
    };
    println!(
        "{label}: {n} round trips back to back: mean {:.1} µs (wall {:.1} µs each) | p50 {:.1} µs | p99 {:.1} µs{cpu}",
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
    let opts = <Opts as clap::Parser>::parse();
    if let Some([transport, endpoint, creds]) = opts.far.as_deref() {
        return far(&opts, transport, endpoint, creds);
    }
    if let Some([endpoint, creds]) = opts.router.as_deref() {
        let _router = star_session(endpoint, creds, "router");
        println!("ready");
        // Route until the near side closes this process's standard input.
        let _ = std::io::stdin().read_to_end(&mut Vec::new());
        return;
    }
    let me = std::env::current_exe().expect("this program's path");
    let private = ratelab::distributed::credentials::PrivateDir::new().expect("a folder");
    let creds =
        Credentials::generate("floor", &["near".into(), "far".into()]).expect("credentials");
    let creds = private.write("floor", &creds).expect("written");
    let creds = creds.to_string_lossy().into_owned();
    for transport in ["zenoh-tls", "zenoh-tcp", "tcp", "zenoh-router"] {
        let chosen = opts.transport.as_deref();
        // The star is measured only when asked for.
        if chosen.is_some_and(|t| t != transport)
            || (chosen.is_none() && transport == "zenoh-router")
        {
            continue;
        }
        let addr = format!("127.0.0.1:{}", free_port());
        let endpoint = match transport {
            "zenoh-tls" => format!("tls/{addr}"),
            "zenoh-tcp" => format!("tcp/{addr}"),
            "zenoh-router" => format!("tls/{addr}"),
            _ => addr.clone(),
        };
        // The star's router, as a process of its own (the launcher's), before either side.
        let router = (transport == "zenoh-router").then(|| {
            let mut r = Command::new(&me)
                .args(["--router", &endpoint, &creds])
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .spawn()
                .expect("the router process starts");
            let mut ready = String::new();
            BufReader::new(r.stdout.take().expect("its stdout"))
                .read_line(&mut ready)
                .ok();
            r
        });
        let mut child = Command::new(&me)
            .args(opts.for_far())
            .args(["--far", transport, &endpoint, &creds])
            .stdout(Stdio::piped())
            .spawn()
            .expect("the far process starts");
        let mut ready = String::new();
        let stdout = child.stdout.take().expect("its stdout");
        BufReader::new(stdout).read_line(&mut ready).ok();
        let mut link: Box<dyn Link> = match transport {
            "zenoh-tls" | "zenoh-tcp" | "zenoh-router" => {
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
                floor::wait_matched(&publisher);
                Box::new(ZenohLink {
                    extra_puts: opts.extra_puts,
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
            "zenoh-router" => {
                "bare Zenoh through a router (two clients of it, ratelab's session config)"
            }
            _ => "bare TCP socket (nodelay, blocking)",
        };
        if opts.round_trips == DEFAULT_ROUND_TRIPS {
            one_way(link.as_mut(), label, 50, 500);
            one_way(link.as_mut(), label, 1000, 5000);
        }
        round_trips(link.as_mut(), label, opts.round_trips, &opts, child.id());
        link.send(encode(2, 0, 0));
        let _ = child.wait();
        if let Some(mut r) = router {
            drop(r.stdin.take());
            let _ = r.wait();
        }
    }
}
