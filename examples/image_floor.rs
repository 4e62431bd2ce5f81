//! What a camera's frames cost through bare Zenoh on this host, for BENCHMARKS.md (issue 51):
//! a payload of `--bytes` (a 1 MiB frame by default) put `--rate-hz` times a second from one
//! process to another, with Zenoh's session opened exactly as ratelab opens it (mutual TLS,
//! the graph's access control, ratelab's runtime threads, and shared memory unless
//! `RATELAB_SHARED_MEMORY=off`: each frame written once into a buffer of the publisher's
//! pool, as ratelab writes a large sample), and nothing else of ratelab's on the path.
//! `scripts/bench-image.py` runs it beside ratelab's own launch of a camera graph, in one
//! sitting, with shared memory on and off.
//!
//! ```sh
//! target/release/examples/image_floor                        # 1 MiB at 30 Hz, 300 frames
//! RATELAB_SHARED_MEMORY=off target/release/examples/image_floor --count 300
//! ```
//!
//! It starts one copy of itself as the subscriber (`--far ENDPOINT CREDENTIALS`). Each
//! payload begins with its send time on the host's `CLOCK_MONOTONIC`; the subscriber's
//! callback takes the latency from it (as ratelab's "wire" latency is measured), checks the
//! payload's length, and at the end prints p50, p99 and its CPU time. The publisher writes a
//! fresh payload for each put (a camera's new frame) and prints one line of JSON:
//! `{"bytes", "rate_hz", "sent", "received", "p50_us", "p99_us", "cpu_ms_pub",
//! "cpu_ms_sub", "shared_memory"}`.

#[path = "common/floor.rs"]
mod floor;

use hdrhistogram::Histogram;
use ratelab::distributed::credentials::Credentials;
use ratelab::distributed::wire::mono_now_ns;
use ratelab::distributed::zenoh::bytes::ZBytes;
use ratelab::distributed::zenoh::shm::{Defragment, GarbageCollect, ShmProviderBuilder};
use ratelab::distributed::{shared_memory, zenoh::Wait, SHM_POOL_BYTES};
use std::io::{BufRead, BufReader};
use std::process::{Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The payload that ends a run: its length alone says so.
const END_BYTES: usize = 8;

#[derive(clap::Parser, Clone, Debug)]
#[command(about = "A camera's frames through bare Zenoh on this host (BENCHMARKS.md)")]
struct Opts {
    /// Bytes per payload (at least 16).
    #[arg(long, default_value_t = 1 << 20, value_parser = clap::value_parser!(u64).range(16..=(64 << 20)))]
    bytes: u64,
    /// Payloads a second.
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u64).range(1..=10_000))]
    rate_hz: u64,
    /// Payloads in all.
    #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    count: u64,
    /// Stamp each frame before it is written, so that its one write is timed (as ratelab's
    /// copy of a frame into its pool was before its nodes drew frames into lent buffers).
    /// By default a frame is written first (a camera's driver filling a loaned buffer) and
    /// stamped as it is put, as ratelab now stamps a frame drawn into a lent buffer.
    #[arg(long)]
    stamp_before_write: bool,
    /// Run as the subscriber: ENDPOINT CREDENTIALS (the publisher starts it).
    #[arg(long, num_args = 2, hide = true)]
    far: Option<Vec<String>>,
}

/// CPU time (user and system) this process has used so far, ms.
fn cpu_ms() -> Option<f64> {
    Some(floor::cpu_ns(std::process::id())? as f64 / 1e6)
}

/// The subscriber: the latency of each payload of the expected length, until the end.
fn far(endpoint: &str, creds: &str, bytes: usize) {
    let session = floor::tls_session(&[endpoint.to_string()], &[], creds, "far");
    let hist = Arc::new(Mutex::new(
        Histogram::<u64>::new_with_bounds(1, 60_000_000_000, 3).expect("valid bounds"),
    ));
    let (tx, done) = crossbeam_channel::bounded::<()>(1);
    let (h, wrong) = (hist.clone(), Arc::new(Mutex::new(0u64)));
    let w = wrong.clone();
    let _sub = session
        .declare_subscriber("ratelab/floor/image")
        .callback(move |s| {
            let now = mono_now_ns();
            let payload = s.payload();
            if payload.len() == END_BYTES {
                let _ = tx.try_send(());
                return;
            }
            let b = payload.to_bytes();
            let sent = u64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
            if b.len() == bytes && b[b.len() - 1] == b[8] {
                let _ = h
                    .lock()
                    .expect("lock")
                    .record(now.saturating_sub(sent).max(1));
            } else {
                *w.lock().expect("lock") += 1;
            }
        })
        .wait()
        .expect("a subscriber");
    let cpu_before = cpu_ms().unwrap_or(0.0);
    println!("ready");
    let _ = done.recv_timeout(Duration::from_secs(3600));
    let h = hist.lock().expect("lock");
    let us = |q: f64| h.value_at_quantile(q) as f64 / 1e3;
    println!(
        "{}",
        serde_json::json!({
            "received": h.len(),
            "wrong": *wrong.lock().expect("lock"),
            "p50_us": us(0.5),
            "p99_us": us(0.99),
            "cpu_ms": cpu_ms().unwrap_or(0.0) - cpu_before,
        })
    );
}

fn main() {
    ratelab::distributed::set_zenoh_runtime().expect("a usable ZENOH_RUNTIME");
    let opts = <Opts as clap::Parser>::parse();
    let bytes = opts.bytes as usize;
    if let Some([endpoint, creds]) = opts.far.as_deref() {
        return far(endpoint, creds, bytes);
    }
    let private = ratelab::distributed::credentials::PrivateDir::new().expect("a folder");
    let creds =
        Credentials::generate("floor", &["near".into(), "far".into()]).expect("credentials");
    let creds = private.write("floor", &creds).expect("written");
    let creds = creds.to_string_lossy().into_owned();
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free port")
        .port();
    let endpoint = format!("tls/127.0.0.1:{port}");
    let mut child = Command::new(std::env::current_exe().expect("this program's path"))
        .args(["--bytes", &opts.bytes.to_string()])
        .args(["--far", &endpoint, &creds])
        .stdout(Stdio::piped())
        .spawn()
        .expect("the subscriber starts");
    let mut lines = BufReader::new(child.stdout.take().expect("its stdout")).lines();
    let _ready = lines.next();
    let session = floor::tls_session(&[], std::slice::from_ref(&endpoint), &creds, "near");
    let publisher = session
        .declare_publisher("ratelab/floor/image")
        .wait()
        .expect("a publisher");
    floor::wait_matched(&publisher);
    let cpu_before = cpu_ms().unwrap_or(0.0);
    // The publisher's pool, as ratelab's processes make theirs (ratelab's sessions leave
    // Zenoh's own copying of large payloads into shared memory off).
    let pool = shared_memory().unwrap_or(true).then(|| {
        ShmProviderBuilder::default_backend(SHM_POOL_BYTES)
            .wait()
            .expect("a shared-memory pool")
    });
    let period = Duration::from_nanos(1_000_000_000 / opts.rate_hz);
    let start = Instant::now();
    for k in 0..opts.count {
        let due = start + period * k as u32;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        // A new frame each time, as a camera writes one: its pixels, then its send time,
        // written once, into a buffer of the pool when it has room, else into memory of its
        // own (then it crosses the socket). A frame in the pool is stamped as it is put,
        // after it is written (drawn into a loaned buffer, as a ratelab node draws into the
        // buffer its topic lent: nothing but the stamp is written after it), or before it
        // with --stamp-before-write; a frame of its own, before it is written (as ratelab
        // writes a sample that crosses the socket after its stamp).
        let shade = (k % 251) as u8;
        let early = opts.stamp_before_write.then(mono_now_ns);
        let shared = pool.as_ref().and_then(|p| {
            p.alloc(bytes)
                .with_policy::<Defragment<GarbageCollect>>()
                .wait()
                .ok()
        });
        let frame: ZBytes = match shared {
            Some(mut frame) => {
                frame.fill(shade);
                let sent = early.unwrap_or_else(mono_now_ns);
                frame[..8].copy_from_slice(&sent.to_le_bytes());
                frame.into()
            }
            None => {
                let sent = early.unwrap_or_else(mono_now_ns);
                let mut frame = vec![shade; bytes];
                frame[..8].copy_from_slice(&sent.to_le_bytes());
                frame.into()
            }
        };
        publisher.put(frame).wait().expect("a put");
    }
    std::thread::sleep(Duration::from_millis(200));
    publisher.put(vec![0u8; END_BYTES]).wait().expect("the end");
    let cpu_pub = cpu_ms().unwrap_or(0.0) - cpu_before;
    let report: serde_json::Value = lines
        .next()
        .and_then(Result::ok)
        .and_then(|l| serde_json::from_str(&l).ok())
        .expect("the subscriber's report");
    let _ = child.wait();
    println!(
        "{}",
        serde_json::json!({
            "bytes": bytes,
            "rate_hz": opts.rate_hz,
            "sent": opts.count,
            "received": report["received"],
            "wrong": report["wrong"],
            "p50_us": report["p50_us"],
            "p99_us": report["p99_us"],
            "cpu_ms_pub": cpu_pub,
            "cpu_ms_sub": report["cpu_ms"],
            "shared_memory": shared_memory().unwrap_or(true),
        })
    );
}
