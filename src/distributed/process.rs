//! One process of a launch (`ratelab process`): a graph's nodes placed in it, in their own OS process: joins the launcher, builds
//! the graph, ticks its own nodes, forwards the topics it publishes to other processes and
//! takes in those it subscribes to, then reports its view of the run.
//!
//! Every process builds the whole graph (so topic and node indices agree everywhere) but
//! ticks only its nodes. A topic it publishes for another process is kept as the chapter's
//! plain latest-wins buffer here (its QoS lives with the subscriber's copy, which sees every
//! message in publish order and so counts exactly what the in-process topic would); it is a
//! bridge element of the graph: each message goes out as a
//! [`WireSample`](super::wire::WireSample) as it is published.
//!
//! [`run_process`] goes through its phases in order: check its options against the graph
//! file, join the launcher (`Joined`), build the graph, wire the topics that cross its
//! boundary (`crossings` decides which), say ready, then run its share of the graph
//! (`Share`) under the virtual clock (in lockstep) or the real one, and report.
//!
//! Its parts: `stepper` (the lockstep under the virtual clock), `real_clock` (its nodes on
//! their threads), `stats` (the live figures it publishes, [`LiveStats`]).

use super::credentials::{Credentials, Role};
use super::lockstep;
use super::wire::{self, ToLauncher, ToProcess, WireSample};
use super::{check_endpoint, open_client, Access, DistError, Keys, REPLY_TIMEOUT};
use crossbeam_channel::{Receiver, RecvTimeoutError};
use ratelab_core::metrics::LatencyStats;
use ratelab_core::qos::TopicQos;
use ratelab_core::runlog::StepRecord;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::graph::{NodeId, TopicId};
use ratelab_runtime::policy::BrainSlot;
use ratelab_runtime::runcore::{CoreOptions, RunCore};
use ratelab_runtime::scheduler::StopFlag;
use ratelab_runtime::summary::GraphState;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

mod real_clock;
mod stats;
mod stepper;

use real_clock::real_clock;
use stats::{held_topics, spawn_figures, Batch, StepTap};
pub use stats::{LiveStats, MAX_BATCH_COUNTERS, MAX_BATCH_STEPS, MAX_BATCH_TICKS, STATS_PERIOD};

/// A process that starts its part of a real-clock run this long after the run's start
/// rejoined it (a process restarted mid-run), rather than starting with it, seconds.
const REJOIN_AFTER_S: f64 = 0.5;

/// How a process is started.
#[derive(Clone, Debug)]
pub struct ProcessOptions {
    /// The graph file's bytes (hashed at join) and its name for messages.
    pub graph_bytes: Vec<u8>,
    /// The graph file's name, for messages.
    pub graph_origin: String,
    /// The process to run (its name in the graph file).
    pub process: String,
    /// Endpoints to connect to (the launcher's router): the process's one link.
    pub connect: Vec<String>,
    /// Endpoints given to listen on (`--listen`): checked, and not used since a launch is a
    /// star: a process links to its launcher's router alone and nothing links to it
    /// ([`super::open_client`]), on one host or across hosts.
    pub listen: Vec<String>,
    /// The launch's credentials, holding this process's identity (`--credentials FILE`).
    pub credentials: Credentials,
    /// Where the process says what happens to it, one line each: joined, ready, started or
    /// rejoined (with the run time), ended. `None`: nothing said. `ratelab process` says them on
    /// its stdout, which a launcher's own children have closed (`/dev/null`), so only a
    /// process started by hand is heard.
    pub say: Option<fn(&str)>,
}

/// One crossing topic's sending end in its publisher's process: the bridge element that
/// puts each message on the wire as it is published, from the topic's tap, under the topic's
/// lock and within the publishing tick (as ROS 2's `publish()` hands a message to its
/// middleware before it returns): a tick's measured time includes its sends.
struct Outlet {
    publisher: zenoh::pubsub::Publisher<'static>,
    /// The topic's index in the graph.
    topic: usize,
    /// Where a sample goes when the tick runs on Zenoh's receive thread past its budget.
    spill: Arc<Spill>,
    /// The newest seq sent since the publishing tick ended last ([`NOT_SENT`]: none).
    newest: AtomicU64,
    /// Messages offered since the publishing tick ended last.
    this_tick: AtomicU64,
    /// The topic's name, for the line that says a message was too large to send.
    name: String,
    /// Whether that line was said (once per topic).
    said_too_large: std::sync::atomic::AtomicBool,
}

/// What is said of a message of `len` bytes (encoded) too large to send.
fn too_large(len: usize) -> String {
    ratelab_core::limits::refusal(
        format_args!(
            "a message of {len} bytes is larger than one may be between processes (at most {}: a sample's {} less its header): not sent, counted lost on the wire",
            ratelab_core::msg::MAX_PAYLOAD_BYTES,
            wire::MAX_SAMPLE_BYTES
        ),
        "MAX_SAMPLE_BYTES",
    )
}

/// [`Outlet::newest`] when nothing was sent.
const NOT_SENT: u64 = u64::MAX;

impl Outlet {
    fn new(
        publisher: zenoh::pubsub::Publisher<'static>,
        topic: usize,
        name: &str,
        spill: Arc<Spill>,
    ) -> Self {
        Outlet {
            publisher,
            topic,
            spill,
            newest: AtomicU64::new(NOT_SENT),
            this_tick: AtomicU64::new(0),
            name: name.to_string(),
            said_too_large: std::sync::atomic::AtomicBool::new(false),
        }
    }

    /// Send one message (called from the topic's tap, as it is published). Past
    /// [`wire::MAX_SENT_PER_TICK`] in one tick the rest of that tick's are not sent (the
    /// subscriber counts them lost on the wire when a later one arrives). Nor is a message
    /// larger encoded than [`ratelab_core::msg::MAX_PAYLOAD_BYTES`], which every receiver refuses:
    /// it stays home, counted lost the same way (the lockstep does not wait for it), and the
    /// first one is said on stderr, naming the topic, its size and the bound.
    fn send(
        &self,
        seq: u64,
        stamp: Nanos,
        origin: Option<Nanos>,
        data: &ratelab_core::msg::MsgData,
    ) {
        if self.this_tick.fetch_add(1, Ordering::Relaxed) >= wire::MAX_SENT_PER_TICK as u64 {
            return;
        }
        let sent_mono_ns = wire::mono_now_ns();
        let payload = data.to_bytes();
        if payload.len() > ratelab_core::msg::MAX_PAYLOAD_BYTES {
            if !self.said_too_large.swap(true, Ordering::Relaxed) {
                eprintln!(
                    "[ratelab] {}: {}",
                    ratelab_core::text::printable(&self.name),
                    too_large(payload.len())
                );
            }
            return;
        }
        let sample = WireSample {
            seq,
            stamp_ns: stamp.0,
            origin_ns: origin.map(|o| o.0),
            sent_mono_ns,
            data: payload,
        };
        let bytes = sample.encode();
        if self.spill.admit(bytes.len()) {
            // Under congestion control `Block` a put fails only when the session is closed,
            // which the run notices on its own.
            let _ = self.publisher.put(bytes).wait();
        } else {
            self.spill.hold(self.topic, bytes);
        }
        self.newest.store(seq, Ordering::Relaxed);
    }

    /// The publishing tick ended: the newest seq it sent, if any (for its report).
    fn tick_ended(&self) -> Option<u64> {
        self.this_tick.store(0, Ordering::Relaxed);
        Some(self.newest.swap(NOT_SENT, Ordering::Relaxed)).filter(|&s| s != NOT_SENT)
    }
}

/// The bytes of samples a lockstep event run on Zenoh's receive thread may put on the wire
/// itself ([`stepper`]). Zenoh's runtime is that one thread here ([`super::ZENOH_RUNTIME`]),
/// so its sending task cannot drain the send queue (two batches of 64 KiB a priority) while
/// a callback puts: past this, a tick's samples are held back and the main thread puts
/// them (and the reports after them), where a full queue only waits. An instant of the
/// chapter's graph puts about 50 bytes of samples a hop; a node that publishes 200
/// messages a tick across processes goes past it.
pub(super) const CALLBACK_SEND_BUDGET: i64 = 4 * 1024;

/// The samples held back from the wire by the current lockstep advance, and its budget.
pub(super) struct Spill {
    /// Bytes the current advance may still put itself (`i64::MAX`: no bound).
    left: std::sync::atomic::AtomicI64,
    /// Samples held back, in publish order: (topic index, encoded sample).
    held: Mutex<std::collections::VecDeque<(usize, Vec<u8>)>>,
}

impl Spill {
    /// No bound: every sample is put as it is published (the real clock; the main thread).
    fn unbounded() -> Arc<Spill> {
        Arc::new(Spill {
            left: std::sync::atomic::AtomicI64::new(i64::MAX),
            held: Mutex::default(),
        })
    }

    /// From now on, the samples may put `budget` bytes themselves (`None`: no bound).
    pub(super) fn set_budget(&self, budget: Option<i64>) {
        self.left
            .store(budget.unwrap_or(i64::MAX), Ordering::SeqCst);
    }

    /// A sample of `len` bytes may go on the wire now: within the budget, and nothing held
    /// back before it (order is kept).
    fn admit(&self, len: usize) -> bool {
        let len = i64::try_from(len).unwrap_or(i64::MAX);
        self.is_empty() && self.left.fetch_sub(len, Ordering::SeqCst) >= len
    }

    fn hold(&self, topic: usize, bytes: Vec<u8>) {
        ratelab_runtime::graph::lock(&self.held).push_back((topic, bytes));
    }

    /// No sample is held back.
    pub(super) fn is_empty(&self) -> bool {
        ratelab_runtime::graph::lock(&self.held).is_empty()
    }
}

/// The crossing topics whose publisher runs here: each one's [`Outlet`], and the samples
/// held back from Zenoh's receive thread.
pub(super) struct Bridge {
    outlets: Vec<Option<Outlet>>,
    /// Per node, the crossing topics it publishes.
    by_node: Vec<Vec<TopicId>>,
    pub(super) spill: Arc<Spill>,
}

impl Bridge {
    /// After node `node`'s event: the (topic index, newest seq sent) of each crossing topic
    /// it sent on, for its report.
    pub(super) fn forward_after(&self, node: usize) -> Vec<(usize, u64)> {
        let Some(topics) = self.by_node.get(node) else {
            return Vec::new();
        };
        topics
            .iter()
            .filter_map(|t| Some((t.0, self.outlets[t.0].as_ref()?.tick_ended()?)))
            .collect()
    }

    /// Put the samples held back on the wire, oldest first (from the main thread).
    ///
    /// # Errors
    /// When the session is closed.
    pub(super) fn put_held(&self) -> zenoh::Result<()> {
        loop {
            let Some((t, bytes)) = ratelab_runtime::graph::lock(&self.spill.held).pop_front()
            else {
                return Ok(());
            };
            if let Some(o) = self.outlets.get(t).and_then(Option::as_ref) {
                o.publisher.put(bytes).wait()?;
            }
        }
    }
}

/// In `seqs` (the newest seq received per topic), topic `t` has received `seq` or anything
/// after it.
fn arrived(seqs: &[Option<u64>], t: TopicId, seq: u64) -> bool {
    seqs.get(t.0).copied().flatten().is_some_and(|s| s >= seq)
}

/// The sequence numbers that have arrived per inbound topic, for the lockstep's waits.
struct Arrivals {
    seqs: Mutex<Vec<Option<u64>>>,
    cv: Condvar,
}

impl Arrivals {
    /// Topic `t` has received `seq` (or anything after it).
    fn has(&self, t: TopicId, seq: u64) -> bool {
        arrived(&ratelab_runtime::graph::lock(&self.seqs), t, seq)
    }

    /// Wait until topic `t` has received `seq` (or anything after it), until `deadline`
    /// or `stop`: whether it has.
    fn wait_for(&self, t: TopicId, seq: u64, deadline: Instant, stop: &StopFlag) -> bool {
        let mut seqs = ratelab_runtime::graph::lock(&self.seqs);
        loop {
            if arrived(&seqs, t, seq) {
                return true;
            }
            let now = Instant::now();
            if now >= deadline || stop.is_stopped() {
                return false;
            }
            let wait = (deadline - now).min(Duration::from_millis(100));
            seqs = self
                .cv
                .wait_timeout(seqs, wait)
                .map(|(g, _)| g)
                .unwrap_or_else(|e| e.into_inner().0);
        }
    }
}

/// How long a process asks again to join while the launcher says a process of its name is
/// still running (one killed a moment ago: its liveliness token is withdrawn when Zenoh
/// sees its link close, on localhost within milliseconds). A second copy of a running
/// process is refused after this.
pub const BUSY_RETRY: Duration = Duration::from_secs(5);

/// Run process `opts.process` until the launcher ends the run (or `stop`).
///
/// # Errors
/// [`DistError`]: bad endpoints, no launcher, a rejected join (another graph file), a run
/// that cannot be built.
pub fn run_process(opts: &ProcessOptions, stop: &StopFlag) -> Result<(), DistError> {
    let file_spec = check_options(opts)?;
    // `RUST_LOG`, when set, selects Zenoh's (and ratelab's) log lines for stderr.
    super::refusals::install();
    let Joined {
        session,
        keys,
        ctl_rx,
        launcher_gone,
        up,
        setup,
        _ctl_sub,
        _launcher_watch,
    } = Joined::join(opts, &file_spec, stop)?;
    let say = |line: String| {
        if let Some(say) = opts.say {
            say(&line);
        }
    };
    let me = &opts.process;
    say(format!(
        "process '{me}' joined graph '{}' at {}",
        file_spec.name,
        opts.connect.join(", ")
    ));
    let send = |m: &ToLauncher| up.put(wire::encode_json(m)).wait();
    // Samples and reports are never dropped under congestion (Zenoh's default drops): a
    // lost one would stall the run.
    let block = zenoh::qos::CongestionControl::Block;
    let cfg = setup.run_config()?;
    let spec = cfg.graph.clone();
    // Virtual clock: the other processes' tick reports as the launcher hands them on,
    // subscribed to before this process says it is ready ([`lockstep::subscribe_relayed`]).
    let virtual_clock = cfg.clock == crate::ClockKind::Virtual;
    let (slot, nudged, lockstep_keys) = match virtual_clock {
        true => {
            let (slot, nudged) = stepper::Slot::shared(spec.clone());
            let declared = declare_lockstep(&session, &keys, &opts.process, &slot)?;
            (Some(slot), nudged, Some(declared))
        }
        false => (None, crossbeam_channel::never(), None),
    };
    let mine = nodes_of(&spec, &opts.process);
    let batch: Arc<Mutex<Batch>> = Arc::default();
    let core = build_share(&cfg, &setup.policy, &mine, &batch)?;
    let handles = core.handles().clone();
    let (inbound, inbound_ends, publishers) = wire_crossings(
        &session,
        &keys,
        &handles,
        (&mine, &opts.process),
        slot.clone(),
    )?;
    let Inbound {
        subscribers,
        arrivals,
        wire_latency,
    } = inbound_ends;
    let tokens = declare_tokens(&session, &keys, &spec, &mine, &opts.process)?;
    // The launcher hears them before any process starts; the subscribing process
    // subscribes before it says it is ready, and the run starts once all are.
    let while_there = (Some(&launcher_gone), REPLY_TIMEOUT);
    for (_, p) in &publishers {
        wait_matching(p, stop, while_there, "the launcher")?;
    }
    let ticked_pub = session
        .declare_publisher(keys.ticked(&opts.process))
        .congestion_control(block)
        .wait()?;
    // --ros2: this process offers its own nodes; the plant's process `/clock` too. Before
    // saying ready: the wait for external nodes must not eat into the run.
    let ros2 = match setup.ros2_domain {
        Some(domain) => {
            Some(super::ros2_offer::installed()?.offer(domain, &cfg, &handles, &mine, stop)?)
        }
        None => None,
    };
    send(&ToLauncher::Ready {
        process: opts.process.clone(),
    })?;
    say(format!(
        "process '{me}' ready ({} clock): its run starts with the launcher's",
        cfg.clock.as_str()
    ));
    let bridge = bridge_outbound(&spec, &handles, publishers);
    let ticks: Arc<Vec<AtomicU64>> =
        Arc::new((0..spec.nodes.len()).map(|_| AtomicU64::new(0)).collect());
    let run_time = Arc::new(AtomicU64::new(0));
    // Live counters for `ratelab top` and `ratelab lab --attach`, every [`STATS_PERIOD`],
    // and once more after the run (its last steps).
    // Dropped under congestion (Zenoh's default): a watcher that stalls must never hold up
    // the run or its reports.
    let stats_pub = session
        .declare_publisher(keys.stats(&opts.process))
        .wait()?;
    let share = Arc::new(Share {
        process: opts.process.clone(),
        cfg,
        handles,
        mine,
        inbound,
        arrivals,
        wire_latency,
        bridge,
        ticks,
        run_time,
        batch,
        joined_at: AtomicU64::new(0),
    });
    let stats_done = StopFlag::new();
    let stats_thread = spawn_figures(share.clone(), stats_pub, stats_done.clone())?;
    let result = run_share(
        core,
        &share,
        (slot.as_ref(), &nudged),
        (&ctl_rx, stop, &launcher_gone),
        // Under --ros2 a tick may wait on Zenoh: never on Zenoh's own thread.
        (ticked_pub, ros2.is_none()),
        (&say, &send),
    );
    stats_done.stop();
    let _ = stats_thread.join();
    if let Some(offered) = ros2 {
        for w in offered.finish() {
            eprintln!("[ratelab] warning: {w}");
        }
    }
    let state = result?;
    // The launcher vanished mid-run (killed): nobody will take the report or print a
    // summary; say so rather than end as if the run had completed.
    if launcher_gone.is_stopped() && !stop.is_stopped() {
        return Err(DistError::Peer(
            "the launcher went away mid-run: this process stopped with it (no summary)".into(),
        ));
    }
    report(&share, state, &send, &say)?;
    // The tokens go only once the launcher has the report (its withdrawal would overtake it).
    await_report_taken(&ctl_rx, stop, &launcher_gone, REPORT_TAKEN_WAIT);
    drop(tokens);
    drop(subscribers);
    drop(lockstep_keys);
    let _ = session.close().wait();
    Ok(())
}

/// The longest a process waits for the launcher's receipt of its report
/// ([`ToProcess::ReportTaken`]) before it leaves anyway: shorter than the launcher gives
/// the processes it started to exit after the run (5 s, then SIGKILL), as a report that
/// came after the launcher stopped collecting gets no receipt.
pub const REPORT_TAKEN_WAIT: Duration = Duration::from_secs(2);

/// Wait until the launcher says it has this process's report ([`ToProcess::ReportTaken`]),
/// for at most `wait`, and not at all on `stop` or once the launcher is gone. Any other
/// control message meanwhile is not for this run (it is over) and is dropped.
fn await_report_taken(
    ctl: &Receiver<ToProcess>,
    stop: &StopFlag,
    launcher_gone: &StopFlag,
    wait: Duration,
) {
    let deadline = Instant::now() + wait;
    while !stop.is_stopped() && !launcher_gone.is_stopped() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return;
        }
        match ctl.recv_timeout(left.min(Duration::from_millis(100))) {
            Ok(ToProcess::ReportTaken) => return,
            Ok(_) | Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => return,
        }
    }
}

/// How a process sends a message to the launcher.
type SendUp<'a> = &'a dyn Fn(&ToLauncher) -> zenoh::Result<()>;

/// The Zenoh publishers of a process's outbound topics.
type Publishers = Vec<(TopicId, zenoh::pubsub::Publisher<'static>)>;

/// Wire the topics crossing this process's boundary (`mine`, the nodes of `process`):
/// the publisher's side of each outbound topic becomes a plain buffer (the subscriber's
/// copy keeps the QoS) and gets a Zenoh publisher that never drops (a lost sample would
/// stall the run), on the key through which the launcher passes its samples on
/// ([`Keys::via`]); each inbound topic is subscribed to, on its key. Returns the inbound
/// topics, their subscriptions and the outbound publishers.
fn wire_crossings(
    session: &zenoh::Session,
    keys: &Keys,
    handles: &ratelab_runtime::graph::GraphHandles,
    (mine, process): (&[NodeId], &str),
    slot: Option<stepper::SharedSlot>,
) -> Result<(Vec<TopicId>, Inbound, Publishers), DistError> {
    let spec = &handles.spec;
    let (inbound, outbound) = crossings(spec, mine);
    for &t in &outbound {
        let _ = handles.topic(t).set_depth(1);
        handles.topic(t).set_qos(TopicQos::default());
        // A buffer for the wire, not a subscription: whatever the subscriber requested is
        // judged in its own process, on its own copy.
        handles.topic(t).set_matched(true);
    }
    let ends = subscribe_inbound(session, keys, spec, handles, (&inbound, slot), process)?;
    let block = zenoh::qos::CongestionControl::Block;
    let publishers = outbound
        .iter()
        .map(|&t| {
            let key = keys.via(&spec.topic(t).name);
            let publisher = session.declare_publisher(key).congestion_control(block);
            Ok((t, publisher.wait()?))
        })
        .collect::<Result<_, DistError>>()?;
    Ok((inbound, ends, publishers))
}

/// The nodes of process `process` (none when the graph places none there).
fn nodes_of(spec: &GraphSpec, process: &str) -> Vec<NodeId> {
    (spec.placement().into_iter())
        .find(|(p, _)| p == process)
        .map(|(_, ids)| ids)
        .unwrap_or_default()
}

/// Build the graph as this process runs it, in a run core (the whole graph built, its own
/// nodes run here, under either clock): the brain loaded where one of its nodes, `mine`,
/// runs it (a `policy` node; `policy` names it), every actuator step handed to `batch`.
///
/// # Errors
/// [`DistError::Usage`] for a brain that cannot be loaded; a graph that cannot be built.
fn build_share(
    cfg: &RunConfig,
    policy: &str,
    mine: &[NodeId],
    batch: &Arc<Mutex<Batch>>,
) -> Result<RunCore, DistError> {
    let spec = &cfg.graph;
    let brain_spec = if mine.iter().any(|&id| spec.node(id).kind.def().uses_brain) {
        policy
    } else {
        "scripted"
    };
    let brain = ratelab_runtime::checkpoint::load_policy(brain_spec)
        .map_err(|e| DistError::Usage(format!("--policy {brain_spec}: {e}")))?;
    let graph = ratelab_runtime::runcore::build_graph(
        cfg,
        BrainSlot::new(brain),
        false,
        vec![Box::new(StepTap(batch.clone()))],
    )?;
    Ok(RunCore::with_graph(cfg, graph, CoreOptions::default()))
}

/// Send this process's view of the run, `state`, with its wire latencies to the launcher,
/// and say so.
fn report(
    share: &Share,
    state: GraphState,
    send: SendUp<'_>,
    say: &dyn Fn(String),
) -> Result<(), DistError> {
    send(&ToLauncher::Report {
        process: share.process.clone(),
        state: Box::new(state),
        wire: share.wire_links(),
    })?;
    say(format!(
        "process '{}' ended: its report went to the launcher, which prints the run's summary",
        share.process
    ));
    Ok(())
}

/// Declare what the lockstep needs of this process under the virtual clock: the other
/// processes' tick reports, as the launcher hands them on, into `slot`. Kept alive for the
/// run.
fn declare_lockstep(
    session: &zenoh::Session,
    keys: &Keys,
    process: &str,
    slot: &stepper::SharedSlot,
) -> Result<zenoh::pubsub::Subscriber<()>, DistError> {
    let slot = slot.clone();
    lockstep::subscribe_relayed(session, keys, process, move |ms| slot.reports(ms))
}

/// Discovery: a liveliness token per node of `mine`, per publisher and per subscriber
/// (with the topic's QoS), as `ratelab top` and the ROS 2 view read them. Kept alive for
/// the run.
fn declare_tokens(
    session: &zenoh::Session,
    keys: &Keys,
    spec: &GraphSpec,
    mine: &[NodeId],
    process: &str,
) -> Result<Vec<zenoh::liveliness::LivelinessToken>, DistError> {
    let mut tokens = Vec::new();
    for &id in mine {
        let n = spec.node(id);
        tokens.push(
            session
                .liveliness()
                .declare_token(keys.node_token(process, &n.name))
                .wait()?,
        );
        let ends = (n.publishes.iter().map(|&t| ("pub", t)))
            .chain(n.subscribes.iter().map(|&t| ("sub", t)));
        for (role, t) in ends {
            let ts = spec.topic(t);
            let key = keys.endpoint_token(role, &ts.name, &ts.qos.short(ts.depth), &n.name);
            tokens.push(session.liveliness().declare_token(key).wait()?);
        }
    }
    Ok(tokens)
}

/// Run this process's share of the graph to its end: in lockstep under the virtual clock
/// (`slot` set), else on the real clock from the launcher's start (or not at all when the
/// launcher stops the run before it starts). Returns its view of the run.
fn run_share(
    core: RunCore,
    share: &Arc<Share>,
    (slot, nudged): (Option<&stepper::SharedSlot>, &Receiver<()>),
    (ctl_rx, stop, launcher_gone): (&Receiver<ToProcess>, &StopFlag, &StopFlag),
    ticked: (zenoh::pubsub::Publisher<'static>, bool),
    (say, send): (&dyn Fn(String), SendUp<'_>),
) -> Result<GraphState, DistError> {
    let me = &share.process;
    match (share.cfg.clock, slot) {
        (crate::ClockKind::Virtual, Some(slot)) => stepper::run_lockstep(
            core,
            share,
            (slot, nudged),
            ctl_rx,
            ticked,
            stop,
            launcher_gone,
        ),
        (crate::ClockKind::Virtual, None) => Err(DistError::Peer(
            "the virtual clock without its lockstep".into(),
        )),
        (crate::ClockKind::Real, _) => match recv_own(ctl_rx, stop, launcher_gone) {
            Err(e) => Err(e),
            // Ended before it started: report the graph as built.
            Ok(ToProcess::Stop { .. }) => {
                Ok(GraphState::capture(&share.handles, Nanos::ZERO, &[], None))
            }
            Ok(ToProcess::Start { start_mono_ns }) => {
                // Started with the run, or restarted into it (a rejoin): say which.
                let at_s = wire::mono_now_ns().saturating_sub(start_mono_ns) as f64 / 1e9;
                say(if at_s > REJOIN_AFTER_S {
                    format!("process '{me}' rejoined the run at t={at_s:.2}s")
                } else {
                    format!("process '{me}' started with the run")
                });
                real_clock(
                    core,
                    share,
                    start_mono_ns,
                    ctl_rx,
                    stop,
                    launcher_gone,
                    send,
                )
            }
            Ok(other) => Err(DistError::Peer(format!("expected a start, got {other:?}"))),
        },
    }
}

/// Check `opts` before anything connects: its graph file parses and places
/// `opts.process`, the credentials are this graph's and this placement's and hold the
/// process's identity, the endpoints are well formed. Returns the graph file's graph.
///
/// # Errors
/// [`DistError::Usage`], one line naming what is wrong.
fn check_options(opts: &ProcessOptions) -> Result<GraphSpec, DistError> {
    let text = std::str::from_utf8(&opts.graph_bytes)
        .map_err(|_| DistError::Usage(format!("{}: not UTF-8 text", opts.graph_origin)))?;
    let file_spec =
        GraphSpec::parse(text, &opts.graph_origin).map_err(|e| DistError::Usage(e.to_string()))?;
    let placement = file_spec.placement();
    if !placement.iter().any(|(p, _)| *p == opts.process) {
        let names: Vec<&str> = placement.iter().map(|(p, _)| p.as_str()).collect();
        return Err(DistError::Usage(format!(
            "graph '{}' has no process '{}' (its processes: {})",
            file_spec.name,
            opts.process,
            ratelab_core::text::listed(names)
        )));
    }
    if opts.connect.is_empty() {
        return Err(DistError::Usage(
            "--connect tls/HOST:PORT is required: the launcher's endpoint".into(),
        ));
    }
    let role = Role::Process(opts.process.clone());
    if opts.credentials.graph != file_spec.name {
        return Err(DistError::Usage(format!(
            "--credentials are for graph '{}', not '{}': were they exported by another launch?",
            opts.credentials.graph, file_spec.name
        )));
    }
    let placed: Vec<String> = placement.iter().map(|(p, _)| p.clone()).collect();
    if opts.credentials.processes != placed {
        return Err(DistError::Usage(format!(
            "--credentials are for processes {:?}, but the graph file places {placed:?}: were they exported by a launch of another version of it?",
            opts.credentials.processes
        )));
    }
    opts.credentials.identity(&role)?;
    for ep in &opts.connect {
        check_endpoint("--connect", ep, false)?;
    }
    for ep in &opts.listen {
        check_endpoint("--listen", ep, true)?;
    }
    Ok(file_spec)
}

/// A process joined to its launcher: its session, the launcher's control messages and the
/// run's settings from the welcome.
struct Joined {
    session: zenoh::Session,
    keys: Keys,
    /// The launcher's control messages to this process.
    ctl_rx: Receiver<ToProcess>,
    /// Set once the launcher's liveliness token is withdrawn.
    launcher_gone: StopFlag,
    /// Where this process speaks to the launcher (its own key).
    up: zenoh::pubsub::Publisher<'static>,
    /// The run's settings.
    setup: Box<wire::Setup>,
    _ctl_sub: zenoh::pubsub::Subscriber<()>,
    _launcher_watch: zenoh::pubsub::Subscriber<()>,
}

impl Joined {
    /// Open the session to `opts.connect`, wait for the launcher, join with the graph
    /// file's hash and wait for the welcome (asking again for [`BUSY_RETRY`] while a
    /// process of this name still runs).
    ///
    /// # Errors
    /// [`DistError`]: the session cannot open, the launcher runs another graph, the join
    /// is refused, the real clock's processes are on hosts whose clocks differ, `stop`.
    fn join(
        opts: &ProcessOptions,
        file_spec: &GraphSpec,
        stop: &StopFlag,
    ) -> Result<Joined, DistError> {
        let role = Role::Process(opts.process.clone());
        let access = Access {
            credentials: &opts.credentials,
            role: &role,
            spec: Some(file_spec),
        };
        // A client of the launcher's router: its one link ([`super::open_client`]).
        let session = open_client(&opts.connect, access)?;
        let keys = Keys::new(&file_spec.name);
        let (ctl_tx, ctl_rx) = crossbeam_channel::bounded::<ToProcess>(4096);
        let _ctl_sub = session
            .declare_subscriber(keys.control(&opts.process))
            .callback(move |s| {
                if let Ok(m) = wire::decode_json::<ToProcess>(&s.payload().to_bytes()) {
                    let _ = ctl_tx.try_send(m);
                }
            })
            .wait()?;
        // The launcher's token: withdrawn, the run is over for us too.
        let launcher_gone = StopFlag::new();
        let _launcher_watch = {
            let gone = launcher_gone.clone();
            session
                .liveliness()
                .declare_subscriber(keys.launcher_token())
                .history(true)
                .callback(move |s| {
                    if s.kind() == zenoh::sample::SampleKind::Delete {
                        gone.stop();
                    }
                })
                .wait()?
        };
        // Control messages and samples are never dropped under congestion (Zenoh's default
        // drops): a lost grant or report would stall the run.
        let block = zenoh::qos::CongestionControl::Block;
        let up = session
            .declare_publisher(keys.up_from(&opts.process))
            .congestion_control(block)
            .wait()?;
        // Not matched at once: a launcher of another graph at the endpoint means this process
        // was given another graph file (the keys carry the graph's name, so the hash exchanged
        // at join never comes): say so now rather than after the wait.
        let soon = Instant::now() + Duration::from_secs(2);
        while Instant::now() < soon && !up.matching_status().wait().is_ok_and(|m| m.matching()) {
            std::thread::sleep(Duration::from_millis(20));
        }
        if !up.matching_status().wait().is_ok_and(|m| m.matching()) {
            let seen = launchers_seen(&session);
            if !seen.is_empty() && !seen.iter().any(|g| g == keys.graph()) {
                return Err(DistError::Usage(format!(
                    "the launcher at {} runs graph '{}', not '{}': was this process given another graph file?",
                    opts.connect.join(", "),
                    seen.join("', '"),
                    keys.graph()
                )));
            }
        }
        // As long as the launcher waits for its processes to be ready: a launch of
        // hundreds starting on a few cores is answered late.
        let patience = super::ready_wait(opts.credentials.processes.len());
        wait_matching(&up, stop, (None, patience), "the launcher")?;
        let send = |m: &ToLauncher| up.put(wire::encode_json(m)).wait();
        let join = ToLauncher::Join {
            process: opts.process.clone(),
            graph_sha256: super::graph_hash(&opts.graph_bytes),
            pid: std::process::id(),
        };
        send(&join)?;
        let first_join = std::time::Instant::now();
        // The answer to the join. The control key is the process name's, so a process of that
        // name already running (this one is a second copy, or rejoins too early) gets its run's
        // messages there too: those are not for this one, which waits on.
        let setup = loop {
            match recv(&ctl_rx, stop, &launcher_gone)? {
                ToProcess::Welcome {
                    setup,
                    launcher_mono_ns,
                } => {
                    let apart_s = wire::mono_now_ns().abs_diff(launcher_mono_ns) as f64 / 1e9;
                    if setup.clock == crate::ClockKind::Real && apart_s > 2.0 {
                        return Err(DistError::Usage(format!(
                            "the real clock needs every process on the launcher's host (the monotonic clocks differ by {apart_s:.0} s); across hosts use --clock virtual"
                        )));
                    }
                    break setup;
                }
                // Started again the moment the one before was killed: the launcher has not
                // yet seen its liveliness token go. Ask again, for a while.
                ToProcess::Reject { busy: true, .. } if first_join.elapsed() < BUSY_RETRY => {
                    // Soon: every message of the gap is a reading lost to the policy.
                    std::thread::sleep(Duration::from_millis(100));
                    send(&join)?;
                }
                ToProcess::Reject { reason, .. } => return Err(DistError::Usage(reason)),
                _ => {}
            }
        };
        Ok(Joined {
            session,
            keys,
            ctl_rx,
            launcher_gone,
            up,
            setup,
            _ctl_sub,
            _launcher_watch,
        })
    }
}

/// Which of `spec`'s topics cross this process's boundary, for the process running nodes
/// `mine`: (inbound: another process publishes, one of `mine` reads; outbound: one of
/// `mine` publishes, another process reads), each in the graph's topic order. The one
/// place this is decided: the subscriptions, the bridges, the waits and the wire figures
/// all follow it.
fn crossings(spec: &GraphSpec, mine: &[NodeId]) -> (Vec<TopicId>, Vec<TopicId>) {
    let owns = |id: NodeId| mine.contains(&id);
    let topics = || (0..spec.topics.len()).map(TopicId);
    let inbound = topics()
        .filter(|&t| {
            let ts = spec.topic(t);
            ts.subscriber().is_some_and(owns) && !owns(ts.publisher)
        })
        .collect();
    let outbound = topics()
        .filter(|&t| {
            let ts = spec.topic(t);
            owns(ts.publisher) && ts.subscriber().is_some_and(|s| !owns(s))
        })
        .collect();
    (inbound, outbound)
}

/// Subscribe to each `inbound` topic's key: each sample is decoded exactly and delivered
/// into the topic's copy here (or refused and counted, [`Refusals`]), its seq noted in the
/// returned [`Arrivals`] and its time on the wire in the returned per-topic latencies.
/// Under the virtual clock each arrival then advances the lockstep in `slot`, on Zenoh's
/// receive thread ([`stepper`]).
///
/// # Errors
/// [`DistError::Zenoh`] when a subscriber cannot be declared.
fn subscribe_inbound(
    session: &zenoh::Session,
    keys: &Keys,
    spec: &GraphSpec,
    handles: &ratelab_runtime::graph::GraphHandles,
    (inbound, slot): (&[TopicId], Option<stepper::SharedSlot>),
    process: &str,
) -> Result<Inbound, DistError> {
    let arrivals = Arc::new(Arrivals {
        seqs: Mutex::new(vec![None; spec.topics.len()]),
        cv: Condvar::new(),
    });
    // One histogram per inbound topic only (about 270 KB each: one per topic of a
    // 1,000-topic graph held 280 MB in every process).
    let wire_latency: Arc<Vec<Mutex<LatencyStats>>> = Arc::new(
        inbound
            .iter()
            .map(|_| Mutex::new(LatencyStats::default()))
            .collect(),
    );
    let mut subscribers = Vec::new();
    let refusals = Arc::new(Refusals::default());
    for (i, &t) in inbound.iter().enumerate() {
        let topic = handles.topic(t).clone();
        let arrivals = arrivals.clone();
        let lat = wire_latency.clone();
        let offset = Mutex::new(None);
        let refusals = refusals.clone();
        let process = process.to_string();
        let slot = slot.clone();
        subscribers.push(
            session
                .declare_subscriber(keys.topic(&spec.topic(t).name))
                .callback(move |s| {
                    let sample = match WireSample::decode(&s.payload().to_bytes()) {
                        Ok(sample) => sample,
                        Err(e) => return refusals.note(&process, topic.name(), &e),
                    };
                    let (seq, sent) = (sample.seq, sample.sent_mono_ns);
                    if let Err(e) =
                        sample.deliver(&topic, &mut ratelab_runtime::graph::lock(&offset))
                    {
                        return refusals.note(&process, topic.name(), &e);
                    }
                    let took = wire::mono_now_ns().saturating_sub(sent);
                    ratelab_runtime::graph::lock(&lat[i]).record(Nanos(took));
                    {
                        let mut seqs = ratelab_runtime::graph::lock(&arrivals.seqs);
                        seqs[t.0] = Some(seq);
                        arrivals.cv.notify_all();
                    }
                    if let Some(slot) = &slot {
                        slot.wake(false);
                    }
                })
                .wait()?,
        );
    }
    Ok(Inbound {
        subscribers,
        arrivals,
        wire_latency,
    })
}

/// This process's inbound topics as [`subscribe_inbound`] set them up.
struct Inbound {
    /// One per inbound topic, kept for the run.
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    /// The newest seq received on each topic.
    arrivals: Arc<Arrivals>,
    /// Per inbound topic (in the order given), the over-the-wire latency of what arrived.
    wire_latency: Arc<Vec<Mutex<LatencyStats>>>,
}

/// Make each crossing topic whose publisher runs here a bridge element (`publishers`: the
/// topic and its key's publisher): its tap sends each message as it is published. Returns
/// the bridge, which says after a local node's event what it published across the
/// boundary and the newest seq sent on each.
fn bridge_outbound(
    spec: &GraphSpec,
    handles: &ratelab_runtime::graph::GraphHandles,
    publishers: Vec<(TopicId, zenoh::pubsub::Publisher<'static>)>,
) -> Arc<Bridge> {
    let spill = Spill::unbounded();
    let mut outlets: Vec<Option<Outlet>> = (0..spec.topics.len()).map(|_| None).collect();
    for (t, p) in publishers {
        outlets[t.0] = Some(Outlet::new(p, t.0, &spec.topic(t).name, spill.clone()));
    }
    // Per node, the crossing topics it publishes.
    let by_node: Vec<Vec<TopicId>> = (0..spec.nodes.len())
        .map(|i| {
            let publishes = &spec.node(NodeId(i)).publishes;
            publishes
                .iter()
                .copied()
                .filter(|t| outlets[t.0].is_some())
                .collect()
        })
        .collect();
    let bridge = Arc::new(Bridge {
        outlets,
        by_node,
        spill,
    });
    // A crossing topic is a bridge element of the graph: its tap sends each message as it
    // is published (held outputs when they go out), in order, so a node that publishes
    // twice in a tick sends both, as in one process. The publishing tick's report then
    // names the newest seq sent, which a process reading the topic under the virtual clock
    // waits for.
    for t in (0..bridge.outlets.len()).filter(|&t| bridge.outlets[t].is_some()) {
        let bridge = bridge.clone();
        handles
            .topic(TopicId(t))
            .add_data_tap(Box::new(move |seq, stamp, origin, data| {
                if let Some(o) = &bridge.outlets[t] {
                    o.send(seq, stamp, origin, &data);
                }
            }));
    }
    bridge
}

/// The next control message: waits as long as the launcher lives (its liveliness token),
/// so processes started by hand may join minutes apart; an error on a stop or when the
/// launcher is gone.
fn recv(
    rx: &Receiver<ToProcess>,
    stop: &StopFlag,
    gone: &StopFlag,
) -> Result<ToProcess, DistError> {
    loop {
        match rx.recv_timeout(Duration::from_millis(50)) {
            Ok(m) => return Ok(m),
            Err(RecvTimeoutError::Disconnected) => {
                return Err(DistError::Peer("the launcher's channel closed".into()))
            }
            Err(RecvTimeoutError::Timeout) if gone.is_stopped() => {
                return Err(DistError::Peer("the launcher went away".into()))
            }
            Err(RecvTimeoutError::Timeout) if stop.is_stopped() => {
                return Err(DistError::Peer("interrupted".into()))
            }
            Err(RecvTimeoutError::Timeout) => {}
        }
    }
}

/// The next control message for this process once welcomed: a busy refusal is for another
/// process of its name asking to join (the control key is the name's: a second copy, or this
/// one's own join that crossed its welcome), never for this one; a receipt of a report is
/// for the copy before this one.
fn recv_own(
    rx: &Receiver<ToProcess>,
    stop: &StopFlag,
    gone: &StopFlag,
) -> Result<ToProcess, DistError> {
    loop {
        match recv(rx, stop, gone)? {
            ToProcess::Reject { busy: true, .. } | ToProcess::ReportTaken => {}
            m => return Ok(m),
        }
    }
}

/// Wait until `p` has a matching subscriber (`who`, for the error): while the launcher
/// lives when `gone` watches it, else for `patience`.
fn wait_matching(
    p: &zenoh::pubsub::Publisher<'_>,
    stop: &StopFlag,
    (gone, patience): (Option<&StopFlag>, Duration),
    who: &str,
) -> Result<(), DistError> {
    let deadline = Instant::now() + patience;
    loop {
        if p.matching_status().wait().is_ok_and(|m| m.matching()) {
            return Ok(());
        }
        if stop.is_stopped() {
            return Err(DistError::Peer("interrupted".into()));
        }
        if gone.is_some_and(StopFlag::is_stopped) {
            return Err(DistError::Peer("the launcher went away".into()));
        }
        if gone.is_none() && Instant::now() >= deadline {
            return Err(DistError::Peer(format!(
                "{who} did not subscribe to {} within {} s",
                p.key_expr(),
                patience.as_secs()
            )));
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The graphs (their names as in their keys) whose launchers this session sees, by their
/// liveliness tokens (at most 16; asked for up to 1 s).
fn launchers_seen(session: &zenoh::Session) -> Vec<String> {
    super::live_tokens(session, "ratelab/*/@launcher", Duration::from_secs(1), 16)
        .iter()
        .filter_map(|key| {
            key.strip_prefix("ratelab/")
                .and_then(|k| k.strip_suffix("/@launcher"))
                .map(str::to_string)
        })
        .collect()
}

/// This process's share of the graph while it runs: what both clocks, the figures thread
/// and the final report read.
struct Share {
    /// Its name.
    process: String,
    /// The run's settings (its graph is `cfg.graph`).
    cfg: RunConfig,
    handles: ratelab_runtime::graph::GraphHandles,
    /// Its nodes, in graph order.
    mine: Vec<NodeId>,
    /// The topics another process publishes and one of its nodes reads.
    inbound: Vec<TopicId>,
    /// The newest seq received on each inbound topic.
    arrivals: Arc<Arrivals>,
    /// Per inbound topic (in the order given), the over-the-wire latency of what arrived.
    wire_latency: Arc<Vec<Mutex<LatencyStats>>>,
    /// The crossing topics it publishes: what a local node's event sent across the
    /// boundary, and the samples held back from Zenoh's receive thread.
    bridge: Arc<Bridge>,
    /// Ticks per node of the graph (its own nodes' counted here).
    ticks: Arc<Vec<AtomicU64>>,
    /// The run time up to which its figures are final, ns.
    run_time: Arc<AtomicU64>,
    /// The steps, ticks and counters since the last figures sent.
    batch: Arc<Mutex<Batch>>,
    /// The run time this process joined at, ns, when it joined a run under way (0: from
    /// the start).
    joined_at: AtomicU64,
}

impl Share {
    /// Its nodes' indices in the graph.
    fn local(&self) -> Vec<usize> {
        self.mine.iter().map(|id| id.0).collect()
    }

    /// Its [`LiveStats`] now.
    fn live_stats(&self) -> LiveStats {
        let (spec, handles, mine) = (&self.cfg.graph, &self.handles, &self.mine);
        let rates = handles.rates_hz();
        LiveStats {
            graph: spec.name.clone(),
            process: self.process.clone(),
            pid: std::process::id(),
            t_ns: self.run_time.load(Ordering::Relaxed),
            nodes: mine
                .iter()
                .map(|&id| {
                    let n = spec.node(id);
                    (
                        n.name.clone(),
                        n.kind_name().to_string(),
                        rates[id.0],
                        self.ticks[id.0].load(Ordering::Relaxed),
                    )
                })
                .collect(),
            topics: held_topics(spec, mine)
                .into_iter()
                .map(|t| (spec.topic(t).name.clone(), handles.topic(t).stats()))
                .collect(),
            wire: self.wire_links(),
            steps: Vec::new(),
            ticks: Vec::new(),
            counters: Vec::new(),
            done: false,
            since_ns: Some(self.joined_at.load(Ordering::Relaxed)).filter(|t| *t > 0),
        }
    }

    /// The over-the-wire latency of each inbound topic so far.
    fn wire_links(&self) -> Vec<wire::WireLink> {
        wire_links(
            &self.process,
            &self.cfg.graph,
            &self.inbound,
            &self.wire_latency,
        )
    }
}

/// The over-the-wire latency of each inbound topic so far (µs, to 0.1); `lat` holds one
/// per inbound topic, in `inbound`'s order ([`subscribe_inbound`]).
fn wire_links(
    process: &str,
    spec: &GraphSpec,
    inbound: &[TopicId],
    lat: &[Mutex<LatencyStats>],
) -> Vec<wire::WireLink> {
    inbound
        .iter()
        .zip(lat)
        .map(|(&t, l)| {
            let l = ratelab_runtime::graph::lock(l);
            let us = |n: Option<Nanos>| {
                n.map_or(0.0, |n| {
                    ratelab_core::metrics::round_to(n.as_micros_f64(), 1)
                })
            };
            wire::WireLink {
                topic: spec.topic(t).name.clone(),
                process: process.to_string(),
                samples: l.count(),
                p50_us: us(l.quantile(0.5)),
                p99_us: us(l.quantile(0.99)),
                max_us: us(l.max()),
                since_ns: None,
            }
        })
        .collect()
}

/// Samples a process refused (malformed, of the wrong type, numbered out of bounds): counted,
/// and said on stderr (which the launcher shows) at the first and then at most every 10 s,
/// so a flood of bad samples cannot flood the terminal. The line holds only what this
/// process wrote (the topic's name from its own graph, the reason), never the sample's text.
#[derive(Default)]
struct Refusals {
    count: AtomicU64,
    /// When the last line was printed, CLOCK_MONOTONIC ns (0: never).
    said_at: AtomicU64,
}

impl Refusals {
    /// Period between two lines, ns.
    const EVERY_NS: u64 = 10_000_000_000;

    fn note(&self, process: &str, topic: &str, reason: &str) {
        let n = self.count.fetch_add(1, Ordering::SeqCst) + 1;
        let now = wire::mono_now_ns().max(1);
        let last = self.said_at.load(Ordering::SeqCst);
        if (last == 0 || now.saturating_sub(last) >= Self::EVERY_NS)
            && self
                .said_at
                .compare_exchange(last, now, Ordering::SeqCst, Ordering::SeqCst)
                .is_ok()
        {
            eprintln!("[ratelab] {process}: {topic}: refused {reason} ({n} refused so far)");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::real_clock::figures_time;
    use super::{crossings, Outlet};
    use crate::wire::{WireSample, MAX_SENT_PER_TICK};
    use ratelab_core::msg::{force::ForceMsg, MsgData};
    use ratelab_core::time::Nanos;
    use ratelab_runtime::graph::spec::GraphSpec;
    use ratelab_runtime::graph::NodeId;
    use zenoh::Wait;

    /// A process leaves on the launcher's receipt of its report, not before: other control
    /// messages meanwhile are dropped; without a receipt it leaves after the wait, and at
    /// once on Ctrl-C or when the launcher is gone.
    #[test]
    fn a_process_waits_for_the_receipt_of_its_report() {
        use super::{await_report_taken, ToProcess};
        use ratelab_runtime::scheduler::StopFlag;
        use std::time::{Duration, Instant};
        let (tx, rx) = crossbeam_channel::unbounded();
        let (stop, gone) = (StopFlag::new(), StopFlag::new());
        let long = Duration::from_secs(60);
        // The receipt after a late stop and horizon: taken, the wait ends there.
        tx.send(ToProcess::Stop {
            at_ns: 0,
            need: Vec::new(),
        })
        .unwrap();
        tx.send(ToProcess::Horizon { until_ns: 1 }).unwrap();
        tx.send(ToProcess::ReportTaken).unwrap();
        tx.send(ToProcess::Horizon { until_ns: 2 }).unwrap();
        let began = Instant::now();
        await_report_taken(&rx, &stop, &gone, long);
        assert!(began.elapsed() < Duration::from_secs(30));
        assert_eq!(rx.try_recv().ok(), Some(ToProcess::Horizon { until_ns: 2 }));
        // No receipt: it leaves after the wait.
        let began = Instant::now();
        await_report_taken(&rx, &stop, &gone, Duration::from_millis(200));
        assert!(began.elapsed() >= Duration::from_millis(200));
        // The launcher gone, or Ctrl-C: at once.
        gone.stop();
        let began = Instant::now();
        await_report_taken(&rx, &stop, &gone, long);
        assert!(began.elapsed() < Duration::from_secs(30));
        let gone = StopFlag::new();
        stop.stop();
        let began = Instant::now();
        await_report_taken(&rx, &stop, &gone, long);
        assert!(began.elapsed() < Duration::from_secs(30));
        // The channel closed (the session's subscriber gone): at once.
        let (tx, rx) = crossbeam_channel::unbounded::<ToProcess>();
        drop(tx);
        await_report_taken(&rx, &StopFlag::new(), &gone, long);
    }

    /// Which topics cross a process's boundary, decided in one place, as a table: the
    /// chapter's graph as `launch --processes` places it, and the whole graph in one.
    #[test]
    fn crossings_follow_the_placement() {
        let spec = GraphSpec::chapter();
        let names = |ids: Vec<ratelab_runtime::graph::TopicId>| -> Vec<String> {
            ids.into_iter()
                .map(|t| spec.topic(t).name.clone())
                .collect()
        };
        let placement = spec.placement();
        let group = |p: &str| -> Vec<NodeId> {
            placement
                .iter()
                .find(|(name, _)| name == p)
                .map(|(_, ids)| ids.clone())
                .unwrap_or_else(|| panic!("no process {p} in {placement:?}"))
        };
        let all: Vec<NodeId> = (0..spec.nodes.len()).map(NodeId).collect();
        // (who, its nodes, inbound, outbound)
        let table = [
            ("robot", group("robot"), vec!["/action"], vec!["/obs"]),
            ("policy", group("policy"), vec!["/obs"], vec!["/action"]),
            ("one process", all, vec![], vec![]),
            ("no node", Vec::new(), vec![], vec![]),
        ];
        for (who, mine, inbound, outbound) in table {
            let (i, o) = crossings(&spec, &mine);
            assert_eq!(
                (names(i), names(o)),
                (
                    inbound.iter().map(|s| s.to_string()).collect::<Vec<_>>(),
                    outbound.iter().map(|s| s.to_string()).collect::<Vec<_>>()
                ),
                "{who}"
            );
        }
    }

    #[test]
    fn a_crossing_topic_sends_each_message_as_it_is_published_and_names_the_newest() {
        // A session of its own, on no network: Zenoh hands a session's puts to its own
        // subscribers.
        let mut config = zenoh::Config::default();
        for (key, value) in [
            ("listen/endpoints", "[]"),
            ("connect/endpoints", "[]"),
            ("scouting/multicast/enabled", "false"),
        ] {
            config.insert_json5(key, value).expect("a Zenoh setting");
        }
        let session = zenoh::open(config).wait().expect("a local session");
        let (tx, rx) = crossbeam_channel::unbounded();
        let _sub = session
            .declare_subscriber("t/action")
            .callback(move |s| {
                let _ = tx.send(WireSample::decode(&s.payload().to_bytes()));
            })
            .wait()
            .expect("a subscriber");
        let publisher = session.declare_publisher("t/action").wait().unwrap();
        let spill = super::Spill::unbounded();
        let bridge = super::Bridge {
            outlets: vec![Some(Outlet::new(publisher, 0, "/action", spill.clone()))],
            by_node: vec![vec![ratelab_runtime::graph::TopicId(0)], vec![]],
            spill: spill.clone(),
        };
        let outlet = bridge.outlets[0].as_ref().unwrap();
        let force = |n: f64| MsgData::new(ForceMsg { newtons: n });
        let got = |seq: u64| {
            let s = rx
                .recv_timeout(std::time::Duration::from_secs(10))
                .expect("the sample, before its tick ends")
                .expect("a sample that decodes");
            assert_eq!(s.seq, seq);
            s
        };
        // Nothing published in a tick: nothing to name.
        assert_eq!(outlet.tick_ended(), None);
        // Two in one tick: each is on the wire as it is published, before the tick ends.
        outlet.send(0, Nanos(20), Some(Nanos(10)), &force(1.5));
        let first = got(0);
        assert_eq!((first.stamp_ns, first.origin_ns), (20, Some(10)));
        assert_eq!(
            first.data,
            force(1.5).to_bytes(),
            "the payload, as published"
        );
        outlet.send(1, Nanos(20), None, &force(-2.0));
        got(1);
        assert_eq!(outlet.tick_ended(), Some(1), "the newest sent");
        assert_eq!(outlet.tick_ended(), None, "a tick that sent nothing");
        // Past the bound in one tick, the rest of that tick's stay home; the next tick
        // sends again.
        for seq in 2..2 + MAX_SENT_PER_TICK as u64 + 10 {
            outlet.send(seq, Nanos(40), None, &force(0.0));
        }
        for seq in 2..2 + MAX_SENT_PER_TICK as u64 {
            got(seq);
        }
        assert_eq!(outlet.tick_ended(), Some(1 + MAX_SENT_PER_TICK as u64));
        outlet.send(500, Nanos(60), None, &force(0.0));
        got(500);
        assert!(rx.try_recv().is_err(), "nothing more was sent");
        // A message too large for a sample (by a byte: the receiver would refuse it) stays
        // home, unnamed in the report, so the lockstep does not wait for it.
        let huge = MsgData::new(ratelab_core::msg::ImageMsg {
            height: 1,
            width: 1,
            encoding: "mono8".into(),
            step: 1,
            data: vec![0u8; ratelab_core::msg::MAX_PAYLOAD_BYTES].into(),
        });
        assert_eq!(
            huge.to_bytes().len(),
            ratelab_core::msg::MAX_PAYLOAD_BYTES + 13
        );
        assert!(
            <ratelab_core::msg::ImageMsg as ratelab_core::msg::Message>::TYPE
                .decode(&huge.to_bytes())
                .is_err()
        );
        outlet.send(501, Nanos(60), None, &huge);
        assert!(super::too_large(ratelab_core::msg::MAX_PAYLOAD_BYTES + 13)
            .ends_with("not sent, counted lost on the wire (ratelab::limits::MAX_SAMPLE_BYTES)"));
        assert_eq!(
            bridge.forward_after(0),
            vec![(0, 500)],
            "the node's report: the newest sent, not the huge one"
        );
        // The next one (the huge one never arrives first: the wire keeps order).
        outlet.send(502, Nanos(80), None, &force(0.0));
        got(502);
        assert_eq!(outlet.tick_ended(), Some(502));
        assert_eq!(
            bridge.forward_after(1),
            vec![],
            "a node that publishes nothing across"
        );
        // On Zenoh's receive thread, past its budget: the rest are held back, in order,
        // even one that would fit, and the report names them as sent; the main thread puts
        // them.
        let len = WireSample {
            seq: 503,
            stamp_ns: 80,
            origin_ns: None,
            sent_mono_ns: crate::wire::mono_now_ns(),
            data: force(0.0).to_bytes(),
        }
        .encode()
        .len() as i64;
        spill.set_budget(Some(2 * len + len / 2));
        for seq in 503..508 {
            outlet.send(seq, Nanos(80), None, &force(0.0));
        }
        got(503);
        got(504);
        assert!(!spill.is_empty(), "three held back");
        spill.set_budget(Some(i64::MAX));
        outlet.send(508, Nanos(80), None, &force(0.0));
        assert!(
            rx.try_recv().is_err(),
            "nothing jumps the samples held back"
        );
        assert_eq!(bridge.forward_after(0), vec![(0, 508)]);
        bridge.put_held().unwrap();
        assert!(spill.is_empty());
        for seq in 505..509 {
            got(seq);
        }
        // No bound again: each goes as it is published.
        spill.set_budget(None);
        outlet.send(509, Nanos(100), None, &force(0.0));
        got(509);
        assert!(spill.is_empty());
    }

    #[test]
    fn the_figures_time_stops_short_of_a_tick_that_may_be_in_progress() {
        const MS: u64 = 1_000_000;
        let end = 10_000 * MS;
        // Both nodes' next ticks are due later than now: the figures are now's.
        assert_eq!(figures_time(15 * MS, end, [20 * MS, 40 * MS]), 15 * MS);
        // The sensor's tick due at 20 ms may be running at 21 ms, its sample not yet kept:
        // the figures stop just before it, whatever the other node.
        assert_eq!(figures_time(21 * MS, end, [20 * MS, 40 * MS]), 20 * MS - 1);
        // A node late by seconds holds them back as long as its tick has not been sampled.
        assert_eq!(
            figures_time(3_000 * MS, end, [20 * MS, 40 * MS]),
            20 * MS - 1
        );
        // Never past the run's end; no local node: now.
        assert_eq!(figures_time(12_000 * MS, end, [u64::MAX]), end);
        assert_eq!(figures_time(5 * MS, end, []), 5 * MS);
        // A first tick due at 0 that has not happened: nothing is final yet.
        assert_eq!(figures_time(1, end, [0]), 0);
    }
}
