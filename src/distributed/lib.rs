//! One graph, many processes, connected over Zenoh.
//!
//! The graph file places each node in a process (`process = "robot"`; by default the plant's
//! nodes share `robot`, every other node runs alone: [`GraphSpec::process_of`]). Under
//! `ratelab launch --processes` the launcher ([`launcher`]) starts one OS process per
//! process (`ratelab process`, [`process`]) and they talk over Zenoh: the launcher's
//! session is a Zenoh router listening on `tls/127.0.0.1:PORT` ([`open_router`]). In a
//! large launch (or `--star`) every process, and every watcher, is a client of it
//! ([`open_client`]): a star, one link each, P links for P processes, and processes never
//! link to each other. In a small launch the launcher starts, the processes are peers that
//! also link to each other ([`open_linked_peer`], [`DIRECT_LINKS_MAX`]), so that a sample or
//! a lockstep report crosses one link, not two.
//!
//! - **Only the graph's own processes.** Every link is TLS 1.3 with mutual
//!   authentication by a certificate authority made for one launch ([`credentials`]), and
//!   the router drops what an identity may not say, by the identity of the link it came on
//!   ([`access`]): a peer without the launch's credentials cannot connect, and a process
//!   cannot publish another's topics, reports or tokens, nor the launcher's control.
//! - **Across hosts** each other host runs a router of its own ([`host_router`], `ratelab
//!   router`) linked to the launcher's, and its processes link to it: one link per host
//!   across the network, as Zenoh deploys a system.
//!
//! - **Topics** are key expressions `ratelab/<graph>/<topic>` ([`Keys`]). Each process
//!   builds the whole graph but ticks only its own nodes; a topic whose publisher and
//!   subscriber sit in different processes is forwarded as [`wire::WireSample`]s and
//!   published into the subscriber's copy of the topic, which keeps the chapter's buffer,
//!   drop rule and QoS, so `dropped` means what it means in-process. Gaps in the
//!   publisher's sequence numbers count as `lost` on the wire.
//! - **Discovery and liveliness** are Zenoh liveliness tokens, one per node and one per
//!   publisher and subscriber carrying its QoS in short (rmw_zenoh encodes its graph the same
//!   way, `docs/design.md`): `ratelab top` lists them, and the launcher sees a process go
//!   once its token has stayed withdrawn for a moment ([`liveliness`]: Zenoh withdraws a
//!   token when the link it was heard over closes, though another may still carry it).
//! - **Time.** Under the real clock the processes share the host's monotonic clock and one
//!   run-time zero, so stamps and sense→act latency stay exact on one host. Under the
//!   virtual clock every process replays the one [`ratelab_runtime::scheduler::VirtualScheduler`]
//!   order of ticks, ticks its own nodes in their turn and reports each tick to the
//!   launcher, which hands every process the others' reports when its turn comes
//!   ([`lockstep`]); the launcher is the time authority through the horizon it sets. The
//!   same seed gives byte-identical metrics in one process and in several.
//! - **Watching.** [`monitor`] is one more client of the launcher's router that sees a
//!   running launch's tokens and reports (the attached lab; `ratelab top` is another,
//!   [`open_client`]); [`refusals`] passes the TLS handshakes Zenoh refused
//!   on to the launcher's log; [`wire`] is what travels (samples, reports, the lockstep's
//!   messages) and how it is encoded.
//! - **ROS 2.** `launch --ros2` offers each process's nodes through [`ros2_offer`], which
//!   the ROS 2 layer beside this crate fills.
#![warn(missing_docs)]

use ratelab_runtime::ClockKind;

pub mod access;
pub mod credentials;
pub mod host_router;
pub mod launcher;
pub mod liveliness;
pub mod lockstep;
pub mod monitor;
pub mod process;
pub mod refusals;
pub mod ros2_offer;
pub mod wire;

/// The Zenoh crate ratelab is built with (for `ratelab top`'s session).
pub use zenoh;

use ratelab_runtime::graph::spec::GraphSpec;
use sha2::Digest;
use zenoh::Wait;

/// Where a launcher listens when not told (`--listen`), and where `ratelab lab --attach`
/// looks when not told (`--connect`): a port of ratelab's own on loopback, next to Zenoh's
/// router port 7447 but not it (a ROS 2 node of rmw_zenoh connects to 7447 by default, and
/// must not find ratelab's launcher there). A launcher that finds it taken listens on a
/// free port instead (and says which).
pub const DEFAULT_ENDPOINT: &str = "tls/127.0.0.1:7449";

/// Any free port on loopback: where each process of a launch linked directly listens for the
/// others ([`open_linked_peer`]; the launcher gives it `--listen` this).
pub const LOOPBACK_ANY: &str = "tls/127.0.0.1:0";

/// How long a process waits for a peer's answer (a join, a ready, a granted tick).
pub const REPLY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(20);

/// How Zenoh keeps the links of one launch's sessions ([`open_router`], [`open_client`]):
/// sized by the launch's processes, so that a small launch keeps Zenoh's defaults and a
/// large one starts on a small machine.
///
/// Every process links to the launcher's router, P TLS links opened at once and accepted
/// by the launcher's one Zenoh thread ([`ZENOH_RUNTIME`]), which also carries every message
/// of the run. These sizes were first measured on a mesh of peers (2,016 links for 64
/// processes on 2 cores, `BENCHMARKS.md`): under Zenoh's defaults handshakes outlasted its
/// 10 s open and accept timeouts and outnumbered its 100 pending links, and a starved
/// Zenoh thread sent no keep-alive for more than its 10 s lease, so links were cut. A star
/// opens far fewer links, but its one router thread carries them all: the same margins
/// stand for a loaded machine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LinkTimings {
    /// The lease this session announces on each link (Zenoh's `transport/link/tx/lease`):
    /// a peer silent on a link this long, not even a keep-alive (one a quarter lease), is
    /// cut off and its tokens go with it. A process frozen or cut off (not exited: a
    /// closed socket is seen at once) is gone after this.
    pub lease: std::time::Duration,
    /// How long a link may take to open or to be accepted once its TLS handshake is done
    /// (Zenoh's `transport/unicast/open_timeout`, `accept_timeout`).
    pub establish: std::time::Duration,
    /// How many accepted links may be establishing at once (Zenoh's
    /// `transport/unicast/accept_pending`). Only holders of the launch's certificates get
    /// this far (mutual TLS comes first).
    pub pending: usize,
}

impl LinkTimings {
    /// The timings for a launch of `processes` processes: Zenoh's defaults (a 10 s lease
    /// and timeouts, 100 pending) for up to 10; beyond, a second of timeout per process,
    /// half a second of lease (past 20) and four pending links (past 25: about two tries
    /// each way per peer). 64 processes: 64 s, 32 s, 256.
    pub fn for_processes(processes: usize) -> LinkTimings {
        let p = u32::try_from(processes).unwrap_or(u32::MAX);
        let at_least =
            |d: std::time::Duration, min_s: u64| d.max(std::time::Duration::from_secs(min_s));
        LinkTimings {
            lease: at_least(std::time::Duration::from_millis(500).saturating_mul(p), 10),
            establish: at_least(std::time::Duration::from_secs(1).saturating_mul(p), 10),
            pending: processes.saturating_mul(4).max(100),
        }
    }
}

/// The most processes a launch may have and keep Zenoh's default link timings and a 5 s
/// connect timeout ([`LinkTimings::for_processes`], [`open_client`]).
pub const SMALL_LAUNCH: usize = 10;

/// How long the processes of a launch of `processes` take to be ready, at most: each
/// starts, links to the launcher's router and says it is ready, the launcher waits for all
/// of them. [`REPLY_TIMEOUT`], half a second more per process (its start on the machine's
/// cores), and 20 ms more per link of the star (one per process, a TLS handshake each with
/// the launcher's one Zenoh thread): 64 processes get 53.3 s, 256 get 153.1 s. (The mesh of
/// peers before it needed 20 ms per pair of processes: 92 s for 64.)
pub fn ready_wait(processes: usize) -> std::time::Duration {
    let p = u32::try_from(processes).unwrap_or(u32::MAX);
    let links = p;
    REPLY_TIMEOUT
        .saturating_add(std::time::Duration::from_millis(500).saturating_mul(p))
        .saturating_add(std::time::Duration::from_millis(20).saturating_mul(links))
}

/// Zenoh's runtime threads in a ratelab process, in the syntax of Zenoh's `ZENOH_RUNTIME`
/// variable (RON): its receive, send, accept and network pools all handed over to one
/// application worker thread, instead of Zenoh's default of six workers over five pools.
/// On a machine with few cores, fewer threads to wake per message is faster: on this
/// 2-core VM, 7 of 7 lockstep runs and 4 of 4 wire-latency figures measured faster with it
/// (BENCHMARKS.md, issue 13; the pools are `zenoh_runtime::ZRuntime`).
pub const ZENOH_RUNTIME: &str = "(rx: (handover: app), tx: (handover: app), \
    acc: (handover: app), net: (handover: app), app: (worker_threads: 1))";

/// Give this process, and every process it starts, [`ZENOH_RUNTIME`], unless the
/// environment already sets a non-empty `ZENOH_RUNTIME` (a user's own setting wins; Zenoh
/// reads it once, at its first use).
///
/// Call it first thing in `main`, before any thread starts: it changes the process's
/// environment, which is not safe while another thread may read it, and swaps the panic
/// hook for a moment.
///
/// # Errors
/// [`DistError::Usage`] when the user's `ZENOH_RUNTIME` is one Zenoh cannot use (not its
/// RON syntax, an unknown pool or field, or no worker thread): Zenoh itself would panic on
/// it at its first use. One Zenoh can use but that runs its receive and send on two
/// threads is accepted here, and every TLS session of a graph refused when opened
/// ([`open_router`], [`open_client`], [`open_linked_peer`], [`open_session`]): Zenoh's
/// TLS link is not safe on it (eclipse-zenoh/zenoh#2557); a session without TLS
/// (`ratelab ros2` to a ROS 2 graph's router) is.
pub fn set_zenoh_runtime() -> Result<(), DistError> {
    if std::env::var_os("ZENOH_RUNTIME").is_none_or(|v| v.is_empty()) {
        std::env::set_var("ZENOH_RUNTIME", ZENOH_RUNTIME);
        return Ok(());
    }
    use std::borrow::Borrow;
    use zenoh_runtime::{RuntimeParam, ZRuntime};
    // Zenoh parses the variable the first time a pool's settings are read, and panics on
    // one it cannot parse: read them here, quietly, where a panic can be caught.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let threads = std::panic::catch_unwind(|| {
        ZRuntime::iter()
            .map(|z| {
                let p: &RuntimeParam = z.borrow();
                p.worker_threads
            })
            .min()
    });
    std::panic::set_hook(hook);
    match threads {
        Ok(Some(n)) if n > 0 => {
            if let Some(why) = shares_a_tls_stream_across_threads() {
                let _ = UNSOUND_OVER_TLS.set(why);
            }
            Ok(())
        }
        Ok(_) => Err(DistError::Usage(
            "ZENOH_RUNTIME gives a Zenoh pool no worker thread (each needs at least one)".into(),
        )),
        Err(_) => Err(DistError::Usage(
            "ZENOH_RUNTIME is not a runtime setting Zenoh can read (its RON syntax, e.g. \
             '(rx: (worker_threads: 2))'; unset it for ratelab's own)"
                .into(),
        )),
    }
}

/// Why the user's `ZENOH_RUNTIME` may not carry a TLS link, once [`set_zenoh_runtime`] has
/// found that it may not ([`open_as`] refuses every session of a graph then).
static UNSOUND_OVER_TLS: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// Whether a `ZENOH_RUNTIME` Zenoh has read (its pools' settings) would let Zenoh's
/// receive and send tasks run at once on two threads: `Some(why)` unless both pools are
/// handed to the same pool of one worker thread. zenoh-link-tls reads and writes one
/// rustls stream from its receive and send tasks with no lock between them
/// (eclipse-zenoh/zenoh#2557, open): on two threads that is a data race, which corrupts
/// memory. Seen here with `(rx: (worker_threads: 2), tx: (worker_threads: 2), app:
/// (worker_threads: 2))`: a process aborted in rustls's `Error::clone` ("memory
/// allocation of 94411650483176 bytes failed"), others hung before the run or in it,
/// 3 launches in 100. Zenoh's own default (rx on 2 workers, tx on 1) is one of these.
fn shares_a_tls_stream_across_threads() -> Option<String> {
    use std::borrow::Borrow;
    use zenoh_runtime::{RuntimeParam, ZRuntime};
    let name = |z: ZRuntime| match z {
        ZRuntime::Application => "app",
        ZRuntime::Acceptor => "acc",
        ZRuntime::TX => "tx",
        ZRuntime::RX => "rx",
        ZRuntime::Net => "net",
    };
    // A pool handed over runs on the other's threads (one hop: Zenoh reads no further).
    let pool = |z: ZRuntime| {
        let p: &RuntimeParam = z.borrow();
        p.handover.unwrap_or(z)
    };
    let (rx, tx) = (pool(ZRuntime::RX), pool(ZRuntime::TX));
    let threads = |z: ZRuntime| {
        let p: &RuntimeParam = z.borrow();
        p.worker_threads
    };
    let runs = if rx != tx {
        format!(
            "Zenoh's receive and send on two pools ({} and {})",
            name(rx),
            name(tx)
        )
    } else if threads(rx) > 1 {
        format!(
            "Zenoh's receive and send on a pool of {} threads ({})",
            threads(rx),
            name(rx)
        )
    } else {
        return None;
    };
    Some(format!(
        "ZENOH_RUNTIME runs {runs}: a graph's links are TLS, and Zenoh's TLS link then reads \
         and writes one stream from two threads at once, which corrupts memory \
         (eclipse-zenoh/zenoh#2557); hand rx and tx to one pool of one worker, e.g. \
         '(rx: (handover: app), tx: (handover: app), app: (worker_threads: 1))', or unset it \
         for ratelab's own"
    ))
}

pub use ratelab_core::limits::MAX_PROCESSES;

/// The longest line of a started process's stderr that the launcher passes on
/// ([`launcher::LaunchOptions::child_stderr`], and on the graph's log key to its lab), bytes
/// (the rest of the line is dropped).
pub const MAX_STDERR_LINE: usize = 4096;

/// Something that stops a multi-process run, as one line.
#[derive(Debug, thiserror::Error)]
pub enum DistError {
    /// A bad endpoint or process name, a graph that cannot be split, a port in use.
    #[error("{0}")]
    Usage(String),
    /// Zenoh could not open a session or declare something.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A peer did not answer in time, or went away.
    #[error("{0}")]
    Peer(String),
    /// The run could not be built.
    #[error(transparent)]
    Run(#[from] ratelab_runtime::runcore::RunError),
    /// The graph file given is not a graph (`FILE:LINE:COL` and why: a front end prints it
    /// as a compiler prints its errors, not behind the command's name).
    #[error(transparent)]
    Graph(#[from] ratelab_runtime::graph::spec::SpecError),
}

impl From<zenoh::Error> for DistError {
    fn from(e: zenoh::Error) -> Self {
        DistError::Zenoh(zenoh_message(&e.to_string()))
    }
}

/// A Zenoh error's first line, without the places in Zenoh's source it names (`… at
/// /root/.cargo/registry/src/…/tcp.rs:61.`): they mean nothing to a user
/// ([`ratelab_core::text::library_message`]).
pub fn zenoh_message(msg: &str) -> String {
    ratelab_core::text::library_message(msg)
}

/// Check a Zenoh endpoint as ratelab uses them: `tls/HOST:PORT` (every link of a graph
/// across processes is mutually authenticated TLS, [`credentials`]), HOST a name or
/// address that resolves, PORT in 0..=65535 (0 only for `--listen`: any free port).
///
/// # Errors
/// [`DistError::Usage`] naming the flag.
pub fn check_endpoint(flag: &str, ep: &str, listen: bool) -> Result<(), DistError> {
    use std::net::ToSocketAddrs;
    let bad = |why: &str| DistError::Usage(format!("{flag} {ep}: {why}"));
    if ep.starts_with("tcp/") {
        return Err(bad(
            "a graph's links are mutually authenticated TLS: write tls/HOST:PORT",
        ));
    }
    let rest = ep
        .strip_prefix("tls/")
        .ok_or_else(|| bad("expected tls/HOST:PORT"))?;
    let (host, port) = rest
        .rsplit_once(':')
        .ok_or_else(|| bad("expected tls/HOST:PORT"))?;
    let port: u16 = port
        .parse()
        .map_err(|_| bad("the port must be a number in 0..=65535"))?;
    if port == 0 && !listen {
        return Err(bad("port 0 means any port: connect to a real one"));
    }
    let host = host.trim_start_matches('[').trim_end_matches(']');
    if host.is_empty() || host.len() > 253 {
        return Err(bad("no host"));
    }
    (host, port)
        .to_socket_addrs()
        .map_err(|e| bad(&format!("the host does not resolve ({e})")))?
        .next()
        .ok_or_else(|| bad("the host does not resolve"))?;
    Ok(())
}

/// The key expressions of one graph, all under `ratelab/<graph>`.
#[derive(Clone, Debug)]
pub struct Keys {
    prefix: String,
}

impl Keys {
    /// The keys of graph `name` (characters a key expression cannot hold become `_`).
    pub fn new(name: &str) -> Keys {
        let chunk: String = name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        Keys {
            prefix: format!("ratelab/{chunk}"),
        }
    }

    /// `ratelab/<graph>`.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// The graph's name as its keys spell it (`<graph>` in `ratelab/<graph>`).
    pub fn graph(&self) -> &str {
        self.prefix.strip_prefix("ratelab/").unwrap_or(&self.prefix)
    }

    /// A topic's key: `ratelab/<graph>/obs` for `/obs`.
    pub fn topic(&self, name: &str) -> String {
        format!("{}/{}", self.prefix, name.trim_matches('/'))
    }

    /// Where a topic's publisher's process puts its samples for the launcher, which passes
    /// each on to the topic's key ([`Keys::topic`]) through its outbox (`launcher/outbox.rs`:
    /// from a thread of its own, as Zenoh's one thread must not wait to send, or a small
    /// one at once): `ratelab/<graph>/@via/obs`.
    pub fn via(&self, name: &str) -> String {
        format!("{}/@via/{}", self.prefix, name.trim_matches('/'))
    }

    /// Where the launcher tells process `p` what to do.
    pub fn control(&self, p: &str) -> String {
        format!("{}/@ctl/{p}", self.prefix)
    }

    /// The launcher's liveliness token: while it exists, the run's authority is alive.
    pub fn launcher_token(&self) -> String {
        format!("{}/@launcher", self.prefix)
    }

    /// Where process `p` tells the launcher ([`wire::ToLauncher`]): its own key, which
    /// only `p` may publish on ([`access`]).
    pub fn up_from(&self, p: &str) -> String {
        format!("{}/@up/{p}", self.prefix)
    }

    /// Every process's [`Keys::up_from`] (the launcher subscribes here).
    pub fn up(&self) -> String {
        format!("{}/@up/*", self.prefix)
    }

    /// A node's liveliness token: `ratelab/<graph>/@node/<process>/<node>`.
    pub fn node_token(&self, process: &str, node: &str) -> String {
        format!("{}/@node/{process}/{node}", self.prefix)
    }

    /// The process of a node's token ([`Keys::node_token`]) of this graph: `policy` of
    /// `ratelab/<graph>/@node/policy/mlp`; `None` for any other key.
    pub fn process_of_node_token<'k>(&self, key: &'k str) -> Option<&'k str> {
        let rest = key
            .strip_prefix(self.prefix.as_str())?
            .strip_prefix("/@node/")?;
        match rest.split_once('/') {
            Some((process, node))
                if !process.is_empty() && !node.is_empty() && !node.contains('/') =>
            {
                Some(process)
            }
            _ => None,
        }
    }

    /// A publisher's or subscriber's token (`role` is `pub` or `sub`), carrying the topic's
    /// QoS in short (spaces as `_`): `ratelab/<graph>/@pub/obs/KL1_latest/sensor`.
    pub fn endpoint_token(&self, role: &str, topic: &str, qos: &str, node: &str) -> String {
        let qos: String = qos
            .chars()
            .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
            .collect();
        format!(
            "{}/@{role}/{}/{qos}/{node}",
            self.prefix,
            topic.trim_matches('/')
        )
    }

    /// Where the launcher answers with the run's settings ([`wire::Setup`]), for watchers.
    pub fn setup(&self) -> String {
        format!("{}/@setup", self.prefix)
    }

    /// Where the launcher says the run is over ([`wire::RunOver`]).
    pub fn ended(&self) -> String {
        format!("{}/@ended", self.prefix)
    }

    /// Where the launcher publishes its progress lines (a process joined, is gone, …).
    pub fn log(&self) -> String {
        format!("{}/@log", self.prefix)
    }

    /// Virtual clock: where process `p` says each event of its nodes is done
    /// ([`wire::Ticked`], several to a message), for the launcher, which hands the reports
    /// on ([`Keys::relayed`]).
    pub fn ticked(&self, p: &str) -> String {
        format!("{}/@ticked/{p}", self.prefix)
    }

    /// Virtual clock: where the launcher hands process `p` the other processes' tick
    /// reports it has not had, when its turn comes ([`lockstep`]; only the launcher's
    /// router may put here, [`access`]).
    pub fn relayed(&self, p: &str) -> String {
        format!("{}/@relayed/{p}", self.prefix)
    }

    /// Virtual clock, a launch linked directly: where process `p` sends the launcher its
    /// tick reports to follow, in batches ([`wire::Ticked`]: once its run passes the time
    /// the launcher's horizon names, [`lockstep::follow_at`], and always before it waits
    /// for the horizon), while the other processes hear each report on [`Keys::ticked`] (or on the
    /// sample it published, [`lockstep::reports_ride_on_samples`]).
    pub fn progress(&self, p: &str) -> String {
        format!("{}/@progress/{p}", self.prefix)
    }

    /// Where each process publishes its live counters for `ratelab top` and `ratelab lab
    /// --attach` ([`process::LiveStats`], with the batch of steps, ticks and counter samples
    /// since the last).
    pub fn stats(&self, p: &str) -> String {
        format!("{}/@stats/{p}", self.prefix)
    }

    /// Where each process publishes its counts alone (its [`process::LiveStats`] without the
    /// batch) for its launcher, which carries a process's counts over when it dies mid-run
    /// and, under the real clock, hears from them that a process is running (silent, heard
    /// again), and for `ratelab top`. Beside [`Keys::stats`], under the same access rules
    /// (`@stats/**`), and matched by no `@stats/*` subscription (the lab's monitor): a
    /// process builds and sends its batch only while a watcher listens.
    pub fn stats_counts(&self, p: &str) -> String {
        format!("{}/@stats/{p}/counts", self.prefix)
    }
}

/// Check that every topic of `spec` makes a valid key expression.
///
/// # Errors
/// [`DistError::Usage`] naming the topic.
pub fn check_keys(spec: &GraphSpec) -> Result<(), DistError> {
    let keys = Keys::new(&spec.name);
    for t in &spec.topics {
        let k = keys.topic(&t.name);
        if zenoh::key_expr::KeyExpr::try_from(k.clone()).is_err() || k.contains("//") {
            return Err(DistError::Usage(format!(
                "topic '{}' does not make a Zenoh key expression ('{k}')",
                t.name
            )));
        }
    }
    // Every process builds its own plant; only the one the actuator steps moves.
    let plant = spec.process_of(spec.actuator);
    for (i, n) in spec.nodes.iter().enumerate() {
        let p = spec.process_of(ratelab_runtime::graph::NodeId(i));
        if n.kind.plant() == ratelab_runtime::graph::kind::Plant::Reads && p != plant {
            return Err(DistError::Usage(format!(
                "sensor '{}' is placed in process '{p}' but the actuator in '{plant}': the nodes that touch the plant must share one process",
                n.name
            )));
        }
    }
    // A topic's subscribers share a process: it holds the topic's counters, and one copy of
    // the topic there feeds every subscription.
    for t in &spec.topics {
        let mut at = t.subscribers.iter().map(|&s| (s, spec.process_of(s)));
        if let Some((first, p)) = at.next() {
            if let Some((other, q)) = at.find(|(_, q)| *q != p) {
                return Err(DistError::Usage(format!(
                    "topic '{}' has subscribers in two processes ('{}' in '{p}', '{}' in '{q}'): a topic's subscribers share a process across processes (place them together, or give each its own topic)",
                    t.name,
                    spec.node(first).name,
                    spec.node(other).name
                )));
            }
        }
    }
    let processes = spec.placement().len();
    if processes > MAX_PROCESSES {
        return Err(DistError::Usage(format!(
            "{}: give nodes a shared `process = \"…\"` (a node without one runs in its own)",
            ratelab_core::limits::refusal(
                format_args!(
                    "graph '{}' places its nodes in {processes} processes; a launch has at most {MAX_PROCESSES}",
                    spec.name
                ),
                "MAX_PROCESSES"
            )
        )));
    }
    Ok(())
}

/// SHA-256 of a graph file's bytes, hex: exchanged at join, so processes given different
/// files refuse to run together.
pub fn graph_hash(bytes: &[u8]) -> String {
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The keys of the liveliness tokens alive now under `selector` (at most `max`; asked for
/// up to `timeout`). Empty when the query cannot be made.
pub fn live_tokens(
    session: &zenoh::Session,
    selector: &str,
    timeout: std::time::Duration,
    max: usize,
) -> Vec<String> {
    let Ok(replies) = session.liveliness().get(selector).timeout(timeout).wait() else {
        return Vec::new();
    };
    let mut keys = Vec::new();
    while keys.len() < max {
        let Ok(reply) = replies.recv() else { break };
        if let Ok(sample) = reply.result() {
            keys.push(sample.key_expr().as_str().to_string());
        }
    }
    keys
}

/// A graph file's bytes, read as untrusted input, parsed: what `ratelab process` and
/// `ratelab router` are given (`origin` names it in errors).
///
/// # Errors
/// [`DistError::Graph`], one line: not UTF-8 (placed at the first byte that is not), or
/// not a graph file.
pub(crate) fn graph_file(bytes: &[u8], origin: &str) -> Result<GraphSpec, DistError> {
    let text = ratelab_core::input::utf8_str(bytes)
        .map_err(|e| DistError::Graph(ratelab_runtime::graph::spec::not_utf8(origin, e)))?;
    Ok(GraphSpec::parse(text, origin)?)
}

/// Are `credentials` those of a launch of `spec`: its graph's name and its processes, in
/// placement order?
///
/// # Errors
/// [`DistError::Usage`], one line, asking whether another launch exported them.
pub(crate) fn credentials_fit(
    credentials: &credentials::Credentials,
    spec: &GraphSpec,
) -> Result<(), DistError> {
    if credentials.graph != spec.name {
        return Err(DistError::Usage(format!(
            "--credentials are for graph '{}', not '{}': were they exported by another launch?",
            credentials.graph, spec.name
        )));
    }
    let placed: Vec<String> = spec.placement().into_iter().map(|(p, _)| p).collect();
    if credentials.processes != placed {
        return Err(DistError::Usage(format!(
            "--credentials are for processes {:?}, but the graph file places {placed:?}: were they exported by a launch of another version of it?",
            credentials.processes
        )));
    }
    Ok(())
}

/// The environment variable that turns Zenoh's shared memory off for a process and every
/// process it starts: `RATELAB_SHARED_MEMORY=off` (`on`, the default, leaves it on).
pub const SHARED_MEMORY_ENV: &str = "RATELAB_SHARED_MEMORY";

/// The smallest sample a process writes into shared memory, bytes: a smaller one fits in
/// one of Zenoh's batches (64 KiB) and crosses the socket. A process whose outbound topics
/// have a field of bytes makes its pool ([`SHM_POOL_BYTES`]) before the run; any other,
/// at its first sample over the threshold. Zenoh locks the pool in memory in the
/// sender and in every process that maps it, plus about 8 MiB of watchdog queues. At Zenoh's
/// own default (3072) the plant's live figures (about 6 KB ten times a second) made the
/// chapter's launch hold 46 MiB more than without shared memory (issue 76); camera frames
/// (300 KiB and up) go through it.
pub const SHM_THRESHOLD_BYTES: usize = 64 * 1024;

/// Which run of a payload that arrived through Zenoh is a buffer in shared memory, if any
/// (its bytes stay in the publisher's pool; what crossed for it is a reference): its one run
/// when Zenoh says so (`as_shm`), or, of several runs, the first of [`SHM_THRESHOLD_BYTES`]
/// or more (a frame its node drew into a lent buffer, sent beside its head: Zenoh has no
/// public way to ask of one run among several, and only a shared-memory run is that long,
/// since Zenoh's receive batches are shorter than 64 KiB and a sample fragmented across
/// them arrives in runs of theirs). For a payload that arrived, not one made locally.
pub(crate) fn shared_run(payload: &zenoh::bytes::ZBytes) -> Option<usize> {
    runs(payload).position(|(_, shared)| shared)
}

/// Each run of a payload that arrived through Zenoh, and whether it is a buffer in shared
/// memory, as [`shared_run`] tells them (a message with two lent frames has two).
pub(crate) fn runs(payload: &zenoh::bytes::ZBytes) -> impl Iterator<Item = (&[u8], bool)> + '_ {
    let one = payload.as_shm().is_some();
    let several = payload.slices().nth(1).is_some();
    payload
        .slices()
        .map(move |run| (run, one || (several && run.len() >= SHM_THRESHOLD_BYTES)))
}

// What [`shared_run`] rests on: Zenoh's receive batches are at most `u16::MAX` bytes (its
// batch size is a u16), so no run that arrived in one reaches the threshold.
const _: () = assert!(SHM_THRESHOLD_BYTES > u16::MAX as usize);

/// The size of a process's shared-memory pool, bytes (Zenoh's default pool size): made
/// before the run by a process whose outbound topics have a field of bytes, else when the
/// process first sends a sample of [`SHM_THRESHOLD_BYTES`] or more. A sample that finds
/// no room in it (its subscribers still hold the earlier ones) crosses the socket.
pub const SHM_POOL_BYTES: usize = 16 << 20;

/// Whether [`open_session`] offers Zenoh's shared memory to its peers: on unless
/// [`SHARED_MEMORY_ENV`] says `off` (unset or empty: on).
///
/// With it on, two processes on one host that both offer it (every ratelab process does)
/// pass a sample of [`SHM_THRESHOLD_BYTES`] or more through a shared segment of the
/// sender's pool ([`SHM_POOL_BYTES`]) rather than through the socket: the sender writes the
/// sample there once and the receiver reads it where it is, so a camera frame crosses
/// without a copy (BENCHMARKS.md measures both). A larger sample than the pool has room for, a peer on
/// another host, or a host without POSIX shared memory (`/dev/shm`) falls back to the
/// socket, with the same QoS, counters and lockstep. The segment is readable by the
/// user's own processes, as the launch's credentials are.
///
/// # Errors
/// [`DistError::Usage`] when the variable holds anything but `on` or `off`.
pub fn shared_memory() -> Result<bool, DistError> {
    match std::env::var(SHARED_MEMORY_ENV).as_deref() {
        Err(std::env::VarError::NotPresent) | Ok("") | Ok("on") => Ok(true),
        Ok("off") => Ok(false),
        Ok(other) => Err(DistError::Usage(format!(
            "{SHARED_MEMORY_ENV} is '{}': on or off",
            ratelab_core::text::printable(other)
        ))),
        Err(std::env::VarError::NotUnicode(_)) => Err(DistError::Usage(format!(
            "{SHARED_MEMORY_ENV} is not text: on or off"
        ))),
    }
}

/// Who a session is and what it knows of the graph: what [`open_session`] needs to
/// authenticate it and to check what it receives ([`access`]).
#[derive(Clone, Copy, Debug)]
pub struct Access<'a> {
    /// The launch's credentials, holding this session's identity.
    pub credentials: &'a credentials::Credentials,
    /// This session's identity.
    pub role: &'a credentials::Role,
    /// The graph's shape, when the session knows it (a watcher does not yet).
    pub spec: Option<&'a GraphSpec>,
}

/// What a session is in a launch ([`open_router`], [`open_client`], [`open_linked_peer`],
/// [`open_session`]): its Zenoh mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    /// The launcher's: a router every other session links to.
    Router,
    /// A process's or a watcher's in the star: a client, linked to the launcher's router
    /// alone.
    Client,
    /// A process's in a launch linked directly: a peer linked to the launcher's router that
    /// also links to the launch's other such peers as the router's gossip tells it of them.
    LinkedPeer,
    /// A peer that links only where it is told (gossip off).
    Peer,
}

impl Mode {
    fn json(self) -> &'static str {
        match self {
            Mode::Router => "\"router\"",
            Mode::Client => "\"client\"",
            Mode::LinkedPeer | Mode::Peer => "\"peer\"",
        }
    }
}

/// The most processes a launch links directly to each other
/// ([`launcher::LaunchOptions::star`], [`open_linked_peer`]): P (P − 1) / 2 links, 45 here.
/// A larger launch is a star alone.
pub const DIRECT_LINKS_MAX: usize = SMALL_LAUNCH;

/// Open the launcher's session (or a host's router's): a Zenoh router listening on `listen`
/// (endpoints already checked), authenticated as `access.role` (the launcher's router,
/// [`credentials::Role::Router`]) by mutual TLS, and dropping what each identity that links
/// to it may not say ([`access`]). Every process and watcher of the launch links to it, and
/// it routes what its clients say to each other. It tells the peers linked to it of each
/// other (Zenoh's gossip), so that the processes of a launch linked directly (`direct`,
/// [`open_linked_peer`]) link to each other; its clients (a star's processes, watchers) and
/// other routers it tells nothing, so no two of them learn of each other.
///
/// # Errors
/// [`DistError::Usage`] when an endpoint cannot be used (a port in use) or the credentials
/// lack the role's identity, else [`DistError::Zenoh`].
pub fn open_router(
    listen: &[String],
    access: Access<'_>,
    direct: bool,
) -> Result<zenoh::Session, DistError> {
    open_as((Mode::Router, direct), listen, &[], access)
}

/// Open a process's or a watcher's session: a Zenoh client of the launcher's router at
/// `connect` (endpoints already checked), authenticated as `access.role` by mutual TLS. It
/// listens nowhere, so its one link is the router's, and everything it receives comes from
/// there (checked by the router on arrival, [`access`]).
///
/// A client rather than a peer linked to the router alone, because of how Zenoh 1.10
/// routes: a router relays between its clients (they make one region, which the router
/// brokers), so what one process publishes reaches every other through it, and liveliness
/// tokens, queries and a publisher's matching status (Zenoh's interests, answered by the
/// router) work as between peers. Peers linked to a router make a region of their own in
/// which each is expected to reach the others directly (peers do not relay for each
/// other): two processes linked as peers to the router alone, gossip off, would not hear
/// each other; with gossip on they would link to each other, the mesh again. A peer linked
/// to the router alone still hears every client through it, but not the peers of a launch
/// linked directly ([`open_linked_peer`]): it is taken for one of them, which reach each
/// other directly. So every watcher is a client.
///
/// # Errors
/// [`DistError::Usage`] when nobody answers at `connect` or the TLS handshake is refused
/// (another launch's credentials), or the credentials lack the role's identity, else
/// [`DistError::Zenoh`].
pub fn open_client(connect: &[String], access: Access<'_>) -> Result<zenoh::Session, DistError> {
    open_as((Mode::Client, false), &[], connect, access)
}

/// Open a process's session in a launch linked directly: a Zenoh peer listening on `listen`
/// (endpoints already checked; `tls/127.0.0.1:0` when the launcher starts it), linked to the
/// launcher's router at `connect` and, as the router's gossip tells it of them, to every
/// other process of the launch that listens (the one whose Zenoh id is greater opens the
/// link). This is how rmw_zenoh deploys ROS 2 by default: a router for discovery, peers
/// linked directly. In Zenoh 1.10 peers linked to each other form a region in which each
/// reaches the others over their own link, so a sample or a lockstep report crosses one link
/// where in the star ([`open_client`]) it crosses two; the router still hears what it
/// subscribes to (the launcher's keys, a watcher's topics) and passes nothing from one peer
/// to another. Authenticated as `access.role` by mutual TLS; every process checks what it
/// receives from another by the graph's access rules ([`access`]), as the router does.
///
/// # Errors
/// As [`open_client`]; also [`DistError::Usage`] when `listen` cannot be listened on.
pub fn open_linked_peer(
    listen: &[String],
    connect: &[String],
    access: Access<'_>,
) -> Result<zenoh::Session, DistError> {
    open_as((Mode::LinkedPeer, true), listen, connect, access)
}

/// Open a Zenoh session in peer mode with multicast scouting and gossip off, listening on
/// `listen` and connecting to `connect` (endpoints already checked): it links to what it
/// connects to and what connects to it, nothing else. Authenticated as `access.role` by
/// mutual TLS, enforcing the graph's access control on what it receives. Tests and the
/// transport-floor examples link two directly.
///
/// # Errors
/// [`DistError::Usage`] when an endpoint cannot be used (a port in use) or the credentials
/// lack the role's identity, else [`DistError::Zenoh`].
pub fn open_session(
    listen: &[String],
    connect: &[String],
    access: Access<'_>,
) -> Result<zenoh::Session, DistError> {
    open_as((Mode::Peer, false), listen, connect, access)
}

/// Open a session of `mode` ([`open_router`], [`open_client`], [`open_linked_peer`],
/// [`open_session`]), in a launch linked directly or not (`direct`: the access rules'
/// [`access::acl`]).
fn open_as(
    (mode, direct): (Mode, bool),
    listen: &[String],
    connect: &[String],
    access: Access<'_>,
) -> Result<zenoh::Session, DistError> {
    if let Some(why) = UNSOUND_OVER_TLS.get() {
        return Err(DistError::Usage(why.clone()));
    }
    let mut config = zenoh::Config::default();
    let json = |v: &[String]| serde_json::to_string(v).unwrap_or_else(|_| "[]".into());
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v)
            .map_err(|e| DistError::Zenoh(format!("config {k}: {e}")))
    };
    set(&mut config, "mode", mode.json())?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    let gossip: &[(&str, &str)] = match mode {
        // Nobody learns of anybody from anybody: each session links where it is told.
        Mode::Client | Mode::Peer => &[("enabled", "false")],
        // The router tells each peer linked to it of the others (one hop: they are all
        // linked to it), and links to nobody it hears of; in a star it has no peers, and a
        // client, a watcher or another host's router is not told.
        Mode::Router => &[
            ("enabled", "true"),
            ("multihop", "false"),
            ("target", r#"{"router": ["peer"]}"#),
            ("autoconnect", r#"{"router": []}"#),
        ],
        // A peer links to the peers it hears of (the launch's other processes that listen;
        // a watcher listens nowhere), one link a pair: the greater Zenoh id opens it.
        Mode::LinkedPeer => &[
            ("enabled", "true"),
            ("multihop", "false"),
            ("autoconnect", r#"{"peer": ["peer"]}"#),
            (
                "autoconnect_strategy",
                r#"{"peer": {"to_router": "always", "to_peer": "greater-zid"}}"#,
            ),
        ],
    };
    for (k, v) in gossip {
        set(&mut config, &format!("scouting/gossip/{k}"), v)?;
    }
    if mode == Mode::Router {
        // A router waits this long after it opens for scouting (500 ms by default): there
        // is none.
        set(&mut config, "scouting/delay", "0")?;
        // What Zenoh's one thread passes on itself (declarations, the answers to queries)
        // must find room in a link's queue, or that thread would wait for room only it can
        // make: Zenoh's most batches a priority (16 of 64 KiB, allocated as used) rather
        // than 2. Samples and reports go out through the launcher's outbox (its own thread,
        // or a small one at once: `launcher/outbox.rs`).
        let sixteen = r#"{"control": 16, "real_time": 16, "interactive_high": 16,
            "interactive_low": 16, "data_high": 16, "data": 16, "data_low": 16,
            "background": 16}"#;
        set(&mut config, "transport/link/tx/queue/size", sixteen)?;
    }
    set(&mut config, "listen/endpoints", &json(listen))?;
    set(&mut config, "connect/endpoints", &json(connect))?;
    // Fail at once on an endpoint that cannot be listened on or connected to, rather than
    // retrying in the background: the caller exits 2 with one line.
    set(&mut config, "listen/exit_on_failure", "true")?;
    set(&mut config, "connect/exit_on_failure", "true")?;
    // A launch's size sets how its links are kept (LinkTimings: Zenoh's defaults for a
    // small one).
    let processes = access.credentials.processes.len();
    let links = LinkTimings::for_processes(processes);
    let ms = |d: std::time::Duration| d.as_millis().to_string();
    // A small launch's process fails in 5 s on an endpoint nobody answers; a large one's
    // processes all connect at once on a loaded machine (64 starting on 2 cores took longer
    // than 5 s to be answered), so they wait as long as a link may take to establish.
    let connect_wait = if processes > SMALL_LAUNCH {
        links.establish
    } else {
        std::time::Duration::from_millis(5000)
    };
    set(&mut config, "connect/timeout_ms", &ms(connect_wait))?;
    for (k, v) in [
        ("transport/unicast/open_timeout", ms(links.establish)),
        ("transport/unicast/accept_timeout", ms(links.establish)),
        (
            "transport/unicast/accept_pending",
            links.pending.to_string(),
        ),
        ("transport/link/tx/lease", ms(links.lease)),
        (
            "transport/shared_memory/enabled",
            shared_memory()?.to_string(),
        ),
        // Zenoh's own copying of large payloads into its pool is off: a process writes its
        // large samples into a pool of its own (process/shm.rs), which reclaims a buffer
        // only when no process holds it. Zenoh's implicit copy allocates with an unsafe
        // garbage collection that may reclaim a buffer a stalled receiver still holds (its
        // watchdog lapsed: zenoh-transport's shm/interop.rs, `_wrap_in_place`; zenoh issue
        // 2628), and a receiver keeps the buffer as the message's pixels.
        (
            "transport/shared_memory/transport_optimization/enabled",
            "false".to_string(),
        ),
    ] {
        set(&mut config, k, &v)?;
    }
    for (k, v) in access.credentials.zenoh_tls(access.role)? {
        set(&mut config, k, &v)?;
    }
    let keys = Keys::new(&access.credentials.graph);
    let acl = access::acl(
        &keys,
        &access.credentials.processes,
        (access.spec, direct),
        access.role,
    );
    set(&mut config, "access_control", &acl.to_string())?;
    zenoh::open(config).wait().map_err(|e| {
        let first = zenoh_message(&e.to_string());
        // Zenoh says only that it could not connect: nobody listens there, or the TLS
        // handshake was refused (most often credentials of another launch).
        let hint = if first.contains("Unable to connect")
            || first.contains("certificate")
            || first.contains("alert")
        {
            " (is the launch running there, and were these credentials made by it? each launch makes its own)"
        } else {
            ""
        };
        DistError::Usage(format!(
            "cannot open a Zenoh session (listen {listen:?}, connect {connect:?}): {first}{hint}"
        ))
    })
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    #[test]
    fn a_small_launch_keeps_zenoh_s_link_timings_and_a_large_one_gets_more() {
        let zenoh = super::LinkTimings {
            lease: Duration::from_secs(10),
            establish: Duration::from_secs(10),
            pending: 100,
        };
        for p in [0, 1, 3, 10] {
            assert_eq!(super::LinkTimings::for_processes(p), zenoh, "{p} processes");
        }
        let big = super::LinkTimings::for_processes(64);
        assert_eq!(big.lease, Duration::from_secs(32));
        assert_eq!(big.establish, Duration::from_secs(64));
        assert_eq!(big.pending, 256);
        // The most a launch may have, and more, without overflow.
        let most = super::LinkTimings::for_processes(super::MAX_PROCESSES);
        assert_eq!(most.lease, Duration::from_secs(128));
        assert!(super::LinkTimings::for_processes(usize::MAX).pending >= most.pending);
        // A star: one link per process to the launcher's router.
        assert_eq!(super::ready_wait(64), Duration::from_millis(53_280));
        assert_eq!(super::ready_wait(3), Duration::from_millis(21_560));
        assert_eq!(super::ready_wait(256), Duration::from_millis(153_120));
        assert!(super::ready_wait(usize::MAX) > super::ready_wait(64));
    }

    #[test]
    fn a_node_token_names_its_process() {
        let keys = super::Keys::new("cartpole");
        let token = keys.node_token("policy", "mlp");
        assert_eq!(keys.process_of_node_token(&token), Some("policy"));
        for other in [
            "ratelab/cartpole/@node/policy",
            "ratelab/cartpole/@node//mlp",
            "ratelab/cartpole/@node/policy/",
            "ratelab/cartpole/@node/policy/mlp/x",
            "ratelab/cartpole/@pub/obs/KL1/sensor",
            "ratelab/other/@node/policy/mlp",
            "ratelab/cartpole2/@node/policy/mlp",
        ] {
            assert_eq!(keys.process_of_node_token(other), None, "{other}");
        }
    }

    #[test]
    fn a_topics_subscribers_share_a_process() {
        let monitor = include_str!("../../graphs/cartpole-monitor.toml");
        let spec = ratelab_runtime::graph::GraphSpec::parse(monitor, "m.toml").unwrap();
        super::check_keys(&spec).unwrap();
        let apart = monitor.replace("process = \"policy\"", "process = \"watch\"");
        let spec = ratelab_runtime::graph::GraphSpec::parse(&apart, "m.toml").unwrap();
        let e = super::check_keys(&spec).unwrap_err().to_string();
        assert!(
            e.contains("topic '/obs' has subscribers in two processes ('policy' in 'policy', 'monitor' in 'watch')"),
            "{e}"
        );
    }
}
