//! One process of a launch (`ratelab process`): a graph's nodes placed in it, in their own OS process: joins the launcher, builds
//! the graph, ticks its own nodes, forwards the topics it publishes to other processes and
//! takes in those it subscribes to, then reports its view of the run.
//!
//! Every process builds the whole graph (so topic and node indices agree everywhere) but
//! ticks only its nodes. A topic it publishes for another process is kept as the chapter's
//! plain latest-wins buffer here (its QoS lives with the subscriber's copy, which sees every
//! message in publish order and so counts exactly what the in-process topic would); it is a
//! bridge element of the graph: each message goes out as a
//! [`super::wire::WireSample`] as it is published.
//!
//! [`run_process`] goes through its phases in order: check its options against the graph
//! file, join the launcher (`Joined`), build the graph, wire the topics that cross its
//! boundary (`crossings` decides which), say ready, then run its share of the graph
//! (`Share`) under the virtual clock (in lockstep) or the real one, and report.
//!
//! Its parts: `join` (joining the launch), `bridge` (the topics that cross its boundary),
//! `stepper` (the lockstep under the virtual clock), `real_clock` (its nodes on their
//! threads), `stats` (the live figures it publishes, [`LiveStats`]).

use super::credentials::{Credentials, Role};
use super::liveliness::TokenWatch;
use super::lockstep;
use super::wire::{self, ToLauncher, ToProcess};
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

mod bridge;
mod join;
mod real_clock;
mod shm;
mod stats;
mod stepper;

use bridge::{bridge_outbound, wire_crossings, wire_links, Arrivals, Bridge, Inbound};
use join::{check_options, recv_own, Joined};

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
    /// Endpoints to connect to (the launcher's router, or its host's router).
    pub connect: Vec<String>,
    /// Endpoints to listen on for the launch's other processes (`--listen`): given, the
    /// process is a peer that links to the others that listen, directly
    /// ([`super::open_linked_peer`]; the launcher gives each process it starts in a launch
    /// linked directly `tls/127.0.0.1:0`). Empty: a client of the router at `connect`, its
    /// one link ([`super::open_client`]).
    pub listen: Vec<String>,
    /// The launch's credentials, holding this process's identity (`--credentials FILE`).
    pub credentials: Credentials,
    /// Where the process says what happens to it, one line each: joined, ready, started or
    /// rejoined (with the run time), ended. `None`: nothing said. `ratelab process` says them on
    /// its stdout, which a launcher's own children have closed (`/dev/null`), so only a
    /// process started by hand is heard.
    pub say: Option<fn(&str)>,
}

/// The bytes of samples a lockstep event run on Zenoh's receive thread may put on the wire
/// itself ([`stepper`]). Zenoh's runtime is that one thread here ([`super::ZENOH_RUNTIME`]),
/// so its sending task cannot drain the send queue (two batches of 64 KiB a priority) while
/// a callback puts: past this, a tick's samples are held back and the main thread puts
/// them (and the reports after them), where a full queue only waits. An instant of the
/// chapter's graph puts about 50 bytes of samples a hop; a node that publishes 200
/// messages a tick across processes goes past it.
pub(super) const CALLBACK_SEND_BUDGET: i64 = 4 * 1024;

/// How long a process asks again to join while the launcher says a process of its name is
/// still running (one killed a moment ago: its liveliness token is withdrawn when Zenoh
/// sees its link close, on localhost within milliseconds). A second copy of a running
/// process is refused after this.
pub const BUSY_RETRY: Duration = Duration::from_secs(5);

/// The publishers of `process`'s live figures, every [`STATS_PERIOD`] and once more after
/// the run (its last steps): whole for `ratelab lab --attach` ([`Keys::stats`]), and its
/// counts alone for the launcher and `ratelab top` ([`Keys::stats_counts`]).
/// Dropped under congestion (Zenoh's default): a watcher that stalls must never hold up
/// the run or its reports. And at Zenoh's lowest priority, `Background`: each priority has
/// its own queue of batches on a link, so a large graph's figures (hundreds of KB, in
/// pieces, every 100 ms) never fill the queue the run's own messages need. At the default
/// priority they did: under the virtual clock the ticks run, and put messages that must
/// arrive, on the one Zenoh thread that empties that queue, so with a watcher attached a
/// put found it full, Zenoh closed the link after 5 s and the process read its launcher
/// gone.
///
/// # Errors
/// [`DistError::Zenoh`] when they cannot be declared.
fn stats_publishers(
    session: &zenoh::Session,
    keys: &Keys,
    process: &str,
) -> Result<stats::Figures, DistError> {
    let declare = |key: String| {
        session
            .declare_publisher(key)
            .priority(zenoh::qos::Priority::Background)
            .wait()
    };
    Ok(stats::Figures {
        whole: declare(keys.stats(process))?,
        counts: declare(keys.stats_counts(process))?,
    })
}

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
    let cfg = setup.run_config()?;
    let spec = cfg.graph.clone();
    // Virtual clock: the other processes' tick reports as the launcher hands them on, or,
    // linked directly, as they send them, subscribed to before this process says it is
    // ready ([`declare_lockstep`]).
    let virtual_clock = cfg.clock == crate::ClockKind::Virtual;
    let (slot, nudged, lockstep_keys) = match virtual_clock {
        true => {
            let (slot, nudged) = stepper::Slot::shared(spec.clone());
            let declared =
                declare_lockstep(&session, (&keys, &spec, setup.direct), &opts.process, &slot)?;
            (Some(slot), nudged, Some(declared))
        }
        false => (None, crossbeam_channel::never(), None),
    };
    let mine = nodes_of(&spec, &opts.process);
    let batch: Arc<Mutex<Batch>> = Arc::default();
    let core = build_share(&cfg, &setup.policy, &mine, &batch)?;
    let handles = core.handles().clone();
    // Two processes linked directly under the virtual clock: the reports ride on the
    // samples, both ways.
    let carry = virtual_clock && lockstep::reports_ride_on_samples(&spec, setup.direct);
    let (inbound, inbound_ends, publishers) = wire_crossings(
        (&session, setup.direct, !virtual_clock),
        &keys,
        &handles,
        (&mine, &opts.process),
        (slot.clone(), carry),
    )?;
    let Inbound {
        subscribers,
        arrivals,
        wire_latency,
    } = inbound_ends;
    let tokens = declare_tokens(&session, &keys, &spec, &mine, &opts.process)?;
    let others = others_of(&spec, me);
    let linked = (setup.direct && !opts.listen.is_empty()).then_some(others.as_slice());
    join::wait_heard(&session, &keys, (&publishers, linked), stop, &launcher_gone)?;
    let mut reporting = stepper::Reporting::declare(&session, &keys, &opts.process, setup.direct)?;
    // --ros2: this process offers its own nodes; the plant's process `/clock` too. Before
    // saying ready: the wait for external nodes must not eat into the run.
    let ros2 = match setup.ros2_domain {
        Some(domain) => {
            Some(super::ros2_offer::installed()?.offer(domain, &cfg, &handles, &mine, stop)?)
        }
        None => None,
    };
    let bridge = bridge_outbound(&spec, &handles, publishers, carry); // and its pool, before the run
    send(&ToLauncher::Ready {
        process: opts.process.clone(),
    })?;
    say(format!(
        "process '{me}' ready ({} clock): its run starts with the launcher's",
        cfg.clock.as_str()
    ));
    let ticks: Arc<Vec<AtomicU64>> =
        Arc::new((0..spec.nodes.len()).map(|_| AtomicU64::new(0)).collect());
    let run_time = Arc::new(AtomicU64::new(0));
    let figures = stats_publishers(&session, &keys, &opts.process)?;
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
    let stats_thread = spawn_figures(share.clone(), figures, stats_done.clone())?;
    let result = run_share(
        core,
        &share,
        (slot.as_ref(), &nudged),
        (&ctl_rx, stop, &launcher_gone),
        {
            // Under --ros2 a tick may wait on Zenoh: never on Zenoh's own thread.
            reporting.callback_ticks = ros2.is_none();
            reporting
        },
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
    if launcher_gone.is_gone() && !stop.is_stopped() {
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
    launcher_gone: &TokenWatch,
    wait: Duration,
) {
    let deadline = Instant::now() + wait;
    while !stop.is_stopped() && !launcher_gone.is_gone() {
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
/// processes' tick reports into `slot`, as the launcher hands them on
/// ([`lockstep::subscribe_relayed`]), and, in a launch linked directly (`direct`), as each
/// process of `spec` sends them ([`lockstep::subscribe_reports`]). Linked directly, the
/// launcher hands on nothing during the run, but at its end it hands on the last reports it
/// took ([`crate::launcher`]'s relay), for the rare one that reached it and not this
/// process (its sender went between its two puts); a report that comes both ways counts
/// once ([`lockstep::TickInbox::accept`]). Kept alive for the run.
fn declare_lockstep(
    session: &zenoh::Session,
    (keys, spec, direct): (&Keys, &GraphSpec, bool),
    process: &str,
    slot: &stepper::SharedSlot,
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, DistError> {
    let take = || {
        let slot = slot.clone();
        move |ms| slot.reports(ms)
    };
    let mut subs = Vec::new();
    let mut ticked = Vec::new();
    for source in report_sources(spec, direct, process) {
        match source {
            ReportSource::Relayed => {
                subs.push(lockstep::subscribe_relayed(session, keys, process, take())?)
            }
            ReportSource::Ticked(p) => ticked.push(p),
        }
    }
    if !ticked.is_empty() {
        subs.extend(lockstep::subscribe_reports(
            session,
            keys,
            &ticked,
            None,
            take(),
        )?);
    }
    Ok(subs)
}

/// The processes of `spec`'s placement other than `process`, in placement order.
fn others_of(spec: &GraphSpec, process: &str) -> Vec<String> {
    (spec.placement().into_iter())
        .map(|(p, _)| p)
        .filter(|p| p != process)
        .collect()
}

/// Where a process hears the other processes' tick reports under the virtual clock.
#[derive(Debug, Clone, PartialEq, Eq)]
enum ReportSource {
    /// As the launcher hands them on to it (`@relayed/<own>`).
    Relayed,
    /// As process `.0` sends them (`@ticked/<.0>`).
    Ticked(String),
}

/// [`declare_lockstep`]'s sources for process `process` of `spec`: always the launcher's
/// hand-on (in a star, every report; linked directly, the last ones at the run's end), and,
/// linked directly (`direct`), each other process's own reports.
fn report_sources(spec: &GraphSpec, direct: bool, process: &str) -> Vec<ReportSource> {
    let mut sources = vec![ReportSource::Relayed];
    if direct {
        sources.extend(
            others_of(spec, process)
                .into_iter()
                .map(ReportSource::Ticked),
        );
    }
    sources
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
    (ctl_rx, stop, launcher_gone): (&Receiver<ToProcess>, &StopFlag, &TokenWatch),
    reporting: stepper::Reporting,
    (say, send): (&dyn Fn(String), SendUp<'_>),
) -> Result<GraphState, DistError> {
    let me = &share.process;
    match (share.cfg.clock, slot) {
        (crate::ClockKind::Virtual, Some(slot)) => stepper::run_lockstep(
            core,
            share,
            (slot, nudged),
            ctl_rx,
            reporting,
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
    /// Per inbound topic (in the order given), the over-the-wire latency of what arrived and
    /// how much was read in place.
    wire_latency: Arc<Vec<Mutex<bridge::Received>>>,
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

#[cfg(test)]
mod tests {
    use super::bridge::{crossings, too_large, Outlet, Spill};
    use super::real_clock::figures_time;
    use super::shm::SharedPool;
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
        use super::{await_report_taken, ToProcess, TokenWatch};
        use ratelab_runtime::scheduler::StopFlag;
        use std::time::{Duration, Instant};
        let (tx, rx) = crossbeam_channel::unbounded();
        let (stop, gone) = (StopFlag::new(), TokenWatch::new());
        let long = Duration::from_secs(60);
        // The receipt after a late stop and horizon: taken, the wait ends there.
        tx.send(ToProcess::Stop {
            at_ns: 0,
            need: Vec::new(),
        })
        .unwrap();
        let horizon = |until_ns| ToProcess::Horizon {
            until_ns,
            follow_at_ns: None,
        };
        tx.send(horizon(1)).unwrap();
        tx.send(ToProcess::ReportTaken).unwrap();
        tx.send(horizon(2)).unwrap();
        let began = Instant::now();
        await_report_taken(&rx, &stop, &gone, long);
        assert!(began.elapsed() < Duration::from_secs(30));
        assert_eq!(rx.try_recv().ok(), Some(horizon(2)));
        // No receipt: it leaves after the wait.
        let began = Instant::now();
        await_report_taken(&rx, &stop, &gone, Duration::from_millis(200));
        assert!(began.elapsed() >= Duration::from_millis(200));
        // The launcher gone (its token withdrawn at boot: long settled), or Ctrl-C: at once.
        gone.note_at(zenoh::sample::SampleKind::Delete, 1);
        let began = Instant::now();
        await_report_taken(&rx, &stop, &gone, long);
        assert!(began.elapsed() < Duration::from_secs(30));
        let gone = TokenWatch::new();
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

    /// Where a process hears the others' tick reports, as a table. Linked directly it hears
    /// each other process itself and still the launcher's hand-on: at a run's end the
    /// launcher hands on the reports of a process that went before its own last ones
    /// reached the others (without that, a process killed mid-run left the other waiting
    /// 20 s for them: seen in CI under load).
    #[test]
    fn a_process_hears_the_launchers_hand_on_in_either_topology() {
        use super::{report_sources, ReportSource::*};
        let spec = GraphSpec::chapter();
        let table = [
            ("robot", false, vec![Relayed]),
            ("robot", true, vec![Relayed, Ticked("policy".into())]),
            ("policy", true, vec![Relayed, Ticked("robot".into())]),
        ];
        for (process, direct, want) in table {
            assert_eq!(
                report_sources(&spec, direct, process),
                want,
                "{process} {direct}"
            );
        }
    }
    /// A session of its own, on no network: Zenoh hands a session's puts to its own
    /// subscribers (also the stepper's tests').
    pub(super) fn local_session() -> zenoh::Session {
        let mut config = zenoh::Config::default();
        for (key, value) in [
            ("listen/endpoints", "[]"),
            ("connect/endpoints", "[]"),
            ("scouting/multicast/enabled", "false"),
        ] {
            config.insert_json5(key, value).expect("a Zenoh setting");
        }
        zenoh::open(config).wait().expect("a local session")
    }

    /// A bridge of one crossing topic, `/action` (topic 0, published by node 0), put on
    /// `session`'s key `t/action` through `spill`.
    fn action_bridge(session: &zenoh::Session, spill: &std::sync::Arc<Spill>) -> super::Bridge {
        let publisher = session.declare_publisher("t/action").wait().unwrap();
        super::Bridge {
            outlets: vec![Some(Outlet::new(
                publisher,
                0,
                "/action",
                (spill.clone(), SharedPool::new(false)),
            ))],
            by_node: vec![vec![ratelab_runtime::graph::TopicId(0)], vec![]],
            spill: spill.clone(),
        }
    }

    #[test]
    fn a_crossing_topic_sends_each_message_as_it_is_published_and_names_the_newest() {
        let session = local_session();
        let (tx, rx) = crossbeam_channel::unbounded();
        let _sub = session
            .declare_subscriber("t/action")
            .callback(move |s| {
                let _ = tx.send(WireSample::decode(&s.payload().to_bytes()));
            })
            .wait()
            .expect("a subscriber");
        let spill = Spill::unbounded();
        let bridge = action_bridge(&session, &spill);
        let outlet = bridge.outlets[0].as_ref().unwrap();
        let force = |n: f64| MsgData::new(ForceMsg { newtons: n });
        let got = |seq: u64| {
            let s = rx
                .recv_timeout(std::time::Duration::from_secs(10))
                .expect("the sample, before its tick ends")
                .expect("a sample that decodes");
            assert_eq!(s.head.seq, seq);
            s
        };
        // Nothing published in a tick: nothing to name.
        assert_eq!(outlet.tick_ended(), None);
        // Two in one tick: each is on the wire as it is published, before the tick ends.
        outlet.send(0, Nanos(20), Some(Nanos(10)), &force(1.5));
        let first = got(0);
        assert_eq!((first.head.stamp_ns, first.head.origin_ns), (20, Some(10)));
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
        assert!(too_large(ratelab_core::msg::MAX_PAYLOAD_BYTES + 13)
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
            head: crate::wire::SampleHead {
                seq: 503,
                stamp_ns: 80,
                origin_ns: None,
                sent_mono_ns: crate::wire::mono_now_ns(),
            },
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
    fn two_processes_linked_directly_send_a_ticks_reports_on_its_last_sample() {
        let session = local_session();
        let (tx, rx) = crossbeam_channel::unbounded();
        let _sub = session
            .declare_subscriber("t/action")
            .callback(move |s| {
                let sample = WireSample::decode(&s.payload().to_bytes()).expect("a sample");
                let carried = s.attachment().map(|a| a.to_bytes().to_vec());
                let _ = tx.send((sample.head.seq, carried));
            })
            .wait()
            .expect("a subscriber");
        let spill = Spill::carrying();
        let bridge = action_bridge(&session, &spill);
        let outlet = bridge.outlets[0].as_ref().unwrap();
        let force = MsgData::new(ForceMsg { newtons: 0.5 });
        let got = || {
            rx.recv_timeout(std::time::Duration::from_secs(10))
                .expect("a sample")
        };
        // Nothing kept: the reports are given back, to go on their own key.
        assert_eq!(bridge.put_kept(Some(vec![7])).unwrap(), Some(vec![7]));
        // Two samples published: kept until their reports go, then both in order, the
        // last carrying the reports.
        outlet.send(0, Nanos(20), None, &force);
        outlet.send(1, Nanos(40), None, &force);
        assert!(rx.try_recv().is_err(), "kept for the reports");
        assert!(spill.is_empty(), "kept, not held back");
        assert_eq!(bridge.put_kept(Some(vec![1, 2, 3])).unwrap(), None);
        assert_eq!(got(), (0, None));
        assert_eq!(got(), (1, Some(vec![1, 2, 3])));
        // A sample held back past the budget goes after those kept before it, in order,
        // with no reports: they go on their own key, once the main thread has put them.
        outlet.send(2, Nanos(60), None, &force);
        spill.set_budget(Some(0));
        outlet.send(3, Nanos(80), None, &force);
        spill.set_budget(None);
        assert_eq!(bridge.put_kept(Some(vec![9])).unwrap(), Some(vec![9]));
        bridge.put_held().unwrap();
        assert_eq!(got(), (2, None));
        assert_eq!(got(), (3, None));
        assert!(rx.try_recv().is_err());
        // A sample kept when there is no report to carry still goes.
        outlet.send(4, Nanos(100), None, &force);
        bridge.put_kept(None).unwrap();
        assert_eq!(got(), (4, None));
    }

    #[test]
    fn linked_directly_a_process_waits_for_each_other_process_s_nodes() {
        use ratelab_runtime::scheduler::StopFlag;
        let session = local_session();
        let keys = crate::Keys::new("g");
        let others = ["policy".to_string(), "actuator".to_string()];
        let stop = StopFlag::new();
        let soon = (None, std::time::Duration::from_millis(300));
        // Nothing announced: both named.
        let _token = session
            .liveliness()
            .declare_token(keys.node_token("policy", "mlp"))
            .wait()
            .unwrap();
        let _elsewhere = session
            .liveliness()
            .declare_token(crate::Keys::new("h").node_token("actuator", "motor"))
            .wait()
            .unwrap();
        let e = super::join::wait_subscribed(&session, &keys, &others, &stop, soon)
            .unwrap_err()
            .to_string();
        assert!(e.contains("linked directly: actuator ("), "{e}");
        assert!(!e.contains("policy"), "{e}");
        // The last one announced while it waits: it returns.
        let late = {
            let (session, keys) = (session.clone(), keys.clone());
            std::thread::spawn(move || {
                std::thread::sleep(std::time::Duration::from_millis(100));
                session
                    .liveliness()
                    .declare_token(keys.node_token("actuator", "motor"))
                    .wait()
                    .unwrap()
            })
        };
        let patient = (None, std::time::Duration::from_secs(20));
        super::join::wait_subscribed(&session, &keys, &others, &stop, patient).unwrap();
        let _late = late.join().unwrap();
        // Stopped: it says so at once.
        stop.stop();
        let more = ["sensor".to_string()];
        let e = super::join::wait_subscribed(&session, &keys, &more, &stop, patient).unwrap_err();
        assert!(e.to_string().contains("interrupted"), "{e}");
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
