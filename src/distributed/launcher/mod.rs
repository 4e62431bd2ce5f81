//! The launcher (`ratelab launch --processes`): starts one `ratelab process` process per
//! process of the graph, admits them (the graph file's hash must match), runs the graph (the
//! time authority under the virtual clock; the common start under the real one), stops
//! every process it started, and merges their reports into one `metrics.json`.
//!
//! The launcher's session is the router of the launch ([`crate::open_router`]): in a star
//! every process and watcher links to it alone, and it passes on what they say to each other,
//! each message checked by the identity that sent it ([`crate::access`]); the crossing
//! topics' samples and the lockstep's reports it passes on from a thread of its own
//! (`outbox`: Zenoh's one thread must never wait to send). A small launch whose processes
//! it starts itself is linked directly ([`LaunchOptions::star`]): its processes also link
//! to each other ([`crate::open_linked_peer`]) and send their samples and reports over
//! those links, and the launcher follows the reports without passing anything on. A program that calls [`launch`]
//! calls [`crate::set_zenoh_runtime`] first thing in its `main`, as the `ratelab` binary
//! does: on Zenoh's default runtime the router's TLS links break under load
//! (eclipse-zenoh/zenoh#2557; the tests get the setting from `.cargo/config.toml`).
//!
//! [`launch`] goes through the phases in order, one module each: the processes it starts
//! (`processes`), who joins (`admission`), the run under the virtual clock
//! (`virtual_run`, with `relay`, which follows the lockstep's reports and hands each
//! process the others' in its turn) or the real one (`real_run`); the session, the summary
//! and the merge of the processes' figures are here.

mod admission;
mod outbox;
mod processes;
mod real_run;
mod relay;
mod virtual_run;

use super::credentials::{Credentials, PrivateDir, Role};
use super::liveliness::Withdrawals;
use super::monitor::Carried;
use super::wire::{self, Setup, ToLauncher, ToProcess};
use super::{check_endpoint, check_keys, Access, DistError, Keys};
use crossbeam_channel::Receiver;
use processes::wait_gate;
use ratelab_core::metrics::Metrics;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::graph::NodeId;
use ratelab_runtime::scheduler::{EndReason, RunEnd, StopFlag};
use ratelab_runtime::summary::{summarize_state, GraphState};
use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

pub use ratelab_runtime::program::Program;

/// How to launch.
#[derive(Clone, Debug)]
pub struct LaunchOptions {
    /// The graph file (`None`: the chapter's, compiled in) and its bytes (hashed at join).
    pub graph_path: Option<PathBuf>,
    /// The graph file's bytes.
    pub graph_bytes: Vec<u8>,
    /// Where to listen (`tls/HOST:PORT`; default [`super::DEFAULT_ENDPOINT`], or a free port
    /// on 127.0.0.1 when that is taken).
    pub listen: Option<String>,
    /// The brain spec (`--policy`).
    pub policy: String,
    /// The program to start the processes with, ratelab's command line (`None`: start none,
    /// and wait for them to be started by hand with `ratelab process`).
    pub exe: Option<Program>,
    /// Where the started processes' stderr goes, a line at a time as `PROCESS: LINE`;
    /// `None`: to the launcher's own stderr, each line as the process wrote it (a
    /// process's stderr is a pipe, not the terminal). Either way each line is also
    /// published on the graph's log key ([`Keys::log`]), where a lab attached from
    /// elsewhere reads it. A lab on the terminal takes them, so that no child writes over
    /// its screen. Lines are cut at [`MAX_STDERR_LINE`] bytes and ended; a line that finds
    /// the channel full is dropped here (give a bounded one: it is on the log key anyway).
    pub child_stderr: Option<crossbeam_channel::Sender<String>>,
    /// The run starts only once this receives (or is told, within [`REPLY_TIMEOUT`](crate::REPLY_TIMEOUT)): a
    /// watcher that must see the whole run (a recording, the lab) says here that it has
    /// figures from every process ([`super::monitor::Watch::run`]). `None`: start when
    /// every process is ready.
    pub start_gate: Option<Receiver<()>>,
    /// Told the endpoint the launcher listens on (`tls/HOST:PORT`), once it listens: a
    /// watcher in the same program connects there. Its progress line `listening on …` says
    /// the same to a person.
    pub listening: Option<crossbeam_channel::Sender<String>>,
    /// Virtual clock: run at this many seconds of run time per second of wall time (the
    /// lab's ×1, so that a person can follow it), the horizon let out no faster; `None`: as
    /// fast as the processes go (headless, a recording, the benchmarks).
    pub pace: Option<f64>,
    /// The launch's credentials, every identity ([`Credentials::generate`] for this graph
    /// and its placement): the launcher's session, the launch's router, is authenticated
    /// with the router's identity ([`Role::Router`], which no file holds), and hands each
    /// process it starts that process's alone (a file in a private folder, removed when
    /// the launch ends).
    pub credentials: Credentials,
    /// `--ros2`: each process offers its own nodes to ROS 2 on this domain, the plant's
    /// process `/clock` too (the launcher's program holds the ROS 2 session, and so the
    /// embedded router when none answered, for the launch's length).
    pub ros2_domain: Option<u32>,
    /// Under the real clock, kill a started process at a run time (SIGKILL, as a crash
    /// would: `launch --kill-process policy@3`), each once. A process whose graph says
    /// `restart = "on-failure"` is then started again and rejoins.
    pub kill_processes: Vec<(String, Nanos)>,
    /// Link every process to the launcher's router alone (the star, `launch --star`), even
    /// in a launch that is otherwise linked directly: one whose processes the launcher
    /// starts itself ([`LaunchOptions::exe`]), [`crate::DIRECT_LINKS_MAX`] or fewer. Linked
    /// directly, every process also links to every other ([`crate::open_linked_peer`]), and
    /// a sample or a lockstep report crosses one link instead of two; processes started by
    /// hand (on other hosts, behind their host's router) make a star.
    pub star: bool,
}

impl LaunchOptions {
    /// Whether a launch of `processes` processes with these options is linked directly
    /// ([`LaunchOptions::star`]).
    pub fn direct(&self, processes: usize) -> bool {
        self.exe.is_some() && !self.star && processes <= crate::DIRECT_LINKS_MAX
    }
}

pub use crate::MAX_STDERR_LINE;

/// How the launcher's progress line that says where it listens begins (`listening on
/// tls/HOST:PORT`), said once it listens ([`LaunchOptions::listening`]).
pub const LISTENING: &str = "listening on ";

/// What a launched run produced.
pub struct LaunchReport {
    /// The merged summary.
    pub metrics: Metrics,
    /// How it ended.
    pub end: RunEnd,
    /// Wall time of the run (after every process was ready).
    pub wall: Duration,
    /// The endpoint the launcher listened on.
    pub endpoint: String,
    /// Over-the-wire latency per topic that crossed processes, in the graph's topic order.
    pub wire: Vec<wire::WireLink>,
    /// Processes that did not report (gone, or failed): their figures are missing.
    pub missing: Vec<String>,
    /// Virtual clock: the lockstep's cost.
    pub lockstep: Option<LockstepCost>,
    /// Real clock: the processes killed on request
    /// ([`LaunchOptions::kill_processes`]), each with the run time it was killed at.
    pub killed: Vec<(String, Nanos)>,
}

/// The launcher's link to its processes: publishers per process and the reply channel.
struct Link {
    keys: Keys,
    session: zenoh::Session,
    up: Receiver<ToLauncher>,
}

impl Link {
    fn tell(&self, process: &str, m: &ToProcess) -> Result<(), DistError> {
        self.session
            .put(self.keys.control(process), wire::encode_json(m))
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait()?;
        Ok(())
    }

    fn recv(&self, timeout: Duration) -> Option<ToLauncher> {
        self.up.recv_timeout(timeout).ok()
    }
}

/// The lockstep's cost, measured by the launcher (virtual clock).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LockstepCost {
    /// Ticks run (in every process).
    pub ticks: u64,
    /// Distinct instants (run times) they ran at.
    pub instants: u64,
    /// Wall time of the run per instant, µs.
    pub us_per_instant: f64,
}

/// A free TCP port on `host` (the OS picks it; it is free when this returns).
fn free_port(host: &str) -> Result<u16, DistError> {
    let host = host.trim_start_matches('[').trim_end_matches(']');
    std::net::TcpListener::bind((host, 0))
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .map_err(|e| DistError::Usage(format!("no free port on {host}: {e}")))
}

/// Merge the processes' views into the graph's: each node's figures from its own process,
/// each topic's from its [holder](ratelab_runtime::graph::spec::TopicSpec::holder)'s process (its
/// subscriber's, whose copy saw every message that crossed, or its publisher's when nobody
/// subscribes); the actuator's measurements from the
/// actuator's process, the brain's label from the policy's. `None` without the actuator's
/// process's report. A topic whose holder was started again mid-run goes on from what the
/// processes before it counted (`carried`: their last figures, up to 100 ms before they
/// died, so what they received after those is counted as lost); a topic whose holder never
/// reported (it died for good) reads its last figures, the rest of what was sent lost.
pub fn merge_states(
    spec: &GraphSpec,
    states: &BTreeMap<String, GraphState>,
    carried: &Carried,
) -> Option<GraphState> {
    let of = |id: NodeId| states.get(&spec.process_of(id));
    let mut merged = of(spec.actuator)?.clone();
    for i in 0..spec.nodes.len() {
        let Some(st) = of(NodeId(i)) else { continue };
        take(&mut merged.rates_hz, &st.rates_hz, i);
        take(&mut merged.ticks, &st.ticks, i);
        // A process started again mid-run counts its nodes' ticks anew.
        if let Some(t) = merged.ticks.get_mut(i) {
            *t = carried.node_ticks(i, *t);
        }
        take(&mut merged.liveliness, &st.liveliness, i);
        if let (Some(d), Some(s)) = (
            merged.timing.as_mut().and_then(|t| t.get_mut(i)),
            st.timing.as_ref().and_then(|t| t.get(i)),
        ) {
            *d = s.clone();
        }
    }
    for (i, t) in spec.topics.iter().enumerate() {
        if let Some(st) = of(t.holder()) {
            take(&mut merged.topics, &st.topics, i);
            take(&mut merged.topic_qos, &st.topic_qos, i);
            if let Some(m) = merged.topics.get_mut(i) {
                *m = carried.continued(i, m);
            }
        }
    }
    if let Some(st) = spec.chain.and_then(|c| of(c.policy)) {
        merged.brain.clone_from(&st.brain);
    }
    merged.exec = merge_exec(spec, states);
    // A topic that crossed processes: what its publisher sent is published; what the
    // subscriber's copy never received (in flight at the end, or sent while it was down)
    // was lost on the wire. Without the subscriber's report only the sending side is known.
    for (i, t) in spec.topics.iter().enumerate() {
        let Some(sub) = t.subscriber() else { continue };
        let (from, to) = (spec.process_of(t.publisher), spec.process_of(sub));
        if from == to {
            continue;
        }
        let sent = states.get(&from).and_then(|s| s.topics.get(i)).copied();
        let (Some(sent), Some(m)) = (sent, merged.topics.get_mut(i)) else {
            continue;
        };
        if states.contains_key(&to) {
            if sent.published > m.published {
                m.lost += sent.published - m.published;
                m.published = sent.published;
            }
        } else {
            // The subscriber's process did not report (it died): what it counted until its
            // last figures (at most 100 ms before it went), and what was sent after those
            // counted as lost, never a clean 0 dropped.
            let mut c = carried.total(i).unwrap_or(ratelab_core::topic::TopicStats {
                depth: t.depth,
                ..Default::default()
            });
            if sent.published > c.published {
                c.lost += sent.published - c.published;
                c.published = sent.published;
            }
            c.last_stamp = sent.last_stamp;
            *m = c;
        }
    }
    Some(merged)
}

/// The executors' figures of a launch: each node's from its own process, each executor's
/// from the process that ran it (an executor never spans processes), in the graph's plan
/// order. `None` when no process measured any (no executors, no compute times). Under the
/// virtual clock every process replays every executor, so any process's figures are the
/// graph's; under the real clock each measured its own.
fn merge_exec(
    spec: &GraphSpec,
    states: &BTreeMap<String, GraphState>,
) -> Option<ratelab_core::executor::ExecFigures> {
    let exec_of = |id: NodeId| {
        states
            .get(&spec.process_of(id))
            .and_then(|s| s.exec.as_ref())
    };
    if states.values().all(|s| s.exec.is_none()) {
        return None;
    }
    let nodes = (0..spec.nodes.len())
        .map(|i| {
            exec_of(NodeId(i))
                .and_then(|x| x.nodes.get(i).cloned())
                .unwrap_or_default()
        })
        .collect();
    let executors = spec
        .execution_plan()
        .executors
        .iter()
        .filter_map(|e| {
            states
                .values()
                .filter_map(|s| s.exec.as_ref())
                .flat_map(|x| &x.executors)
                .find(|f| f.name == e.name && f.kind == e.kind)
                .cloned()
        })
        .collect();
    Some(ratelab_core::executor::ExecFigures { nodes, executors })
}

/// The run time up to which a process's report may count, for [`check_report`]: the run's
/// end, or for a real-clock run the launcher stopped, the time it took the report
/// (`taken_at`) when later. A real-clock process runs on until the launcher's stop reaches
/// it (on a loaded machine, many of its nodes' periods after the end), and its nodes' ticks
/// meanwhile are true ticks; none can come after its report did. The summary still divides
/// by the run's end (`sim_time_s`), so its counts may include those few late ticks.
pub fn report_time(end: &RunEnd, taken_at: Option<Nanos>) -> Nanos {
    taken_at.map_or(end.at, |t| t.max(end.at))
}

/// Check that process `process`'s report could be true of a run that ended at `at`: its
/// vectors have the graph's shape; its nodes ticked no more than their rates allow in that
/// time (two more for phase and the tick at zero); the topics it holds received no more
/// than their publishers could send, dropped no more than they received; and from the
/// plant's process, steps as bounded, latencies finite within the run, a finite angle. A
/// report can still be wrong within these bounds: it comes from the process's own identity
/// ([`super::access`]), so only a process of the launch can send one.
///
/// # Errors
/// What is out of bounds, one line.
pub fn check_report(
    spec: &GraphSpec,
    process: &str,
    st: &GraphState,
    at: Nanos,
) -> Result<(), String> {
    let (n, t) = (spec.nodes.len(), spec.topics.len());
    if st.topics.len() != t
        || st.topic_qos.len() != t
        || st.liveliness.len() != n
        || st.rates_hz.len() != n
        || !(st.ticks.is_empty() || st.ticks.len() == n)
        || st.timing.as_ref().is_some_and(|v| v.len() != n)
        || st.exec.as_ref().is_some_and(|x| {
            x.nodes.len() != n || x.executors.len() > spec.execution_plan().executors.len()
        })
        // A launch takes no commands: no fault is injected into it.
        || !st.injected_faults.is_empty()
    {
        return Err(format!(
            "its figures are not shaped as graph '{}' ({n} nodes, {t} topics)",
            spec.name
        ));
    }
    let bound = |id: NodeId| -> u64 {
        let hz = spec.node(id).rate_hz;
        (at.as_secs_f64() * hz).ceil().min(u64::MAX as f64 / 2.0) as u64 + 2
    };
    for (i, node) in spec.nodes.iter().enumerate() {
        if spec.process_of(NodeId(i)) != process {
            continue;
        }
        if let Some(&ticks) = st.ticks.get(i) {
            if ticks > bound(NodeId(i)) {
                return Err(format!(
                    "node '{}' ticked {ticks} times in {:.2} s at {} Hz (at most {})",
                    node.name,
                    at.as_secs_f64(),
                    node.rate_hz,
                    bound(NodeId(i))
                ));
            }
        }
    }
    for (i, topic) in spec.topics.iter().enumerate() {
        if spec.process_of(topic.holder()) != process {
            continue;
        }
        let c = &st.topics[i];
        // A node may publish any number of times a tick (10⁴ is a true count). What the
        // wire bounds: a process sends at most MAX_SENT_PER_TICK of a tick's messages, and a
        // subscriber counts a gap of at most MAX_SEQ_JUMP between two it receives; no
        // sequence number passes MAX_SEQ.
        let per_tick = (wire::MAX_SENT_PER_TICK as u64).saturating_mul(wire::MAX_SEQ_JUMP + 1);
        let most = bound(topic.publisher)
            .saturating_mul(per_tick)
            .min(wire::MAX_SEQ);
        if c.published > most || c.lost > most || c.dropped > c.published {
            return Err(format!(
                "topic '{}' counted {} published, {} dropped, {} lost in {:.2} s (its publisher sends at most {most})",
                topic.name,
                c.published,
                c.dropped,
                c.lost,
                at.as_secs_f64()
            ));
        }
    }
    let run_ms = at.as_secs_f64() * 1e3;
    let ok_ms = |ms: f64| ms.is_finite() && (0.0..=run_ms + 1.0).contains(&ms);
    if let Some(x) = &st.exec {
        // A response may end after the run (a tick computing at the end): up to the longest
        // compute time past it.
        let late_ms = run_ms + ratelab_core::executor::MAX_COMPUTE.as_millis_f64();
        let ok_response = |ms: f64| ms.is_finite() && (0.0..=late_ms).contains(&ms);
        for (i, f) in x.nodes.iter().enumerate() {
            if spec.process_of(NodeId(i)) != process {
                continue;
            }
            let r = [
                f.response_time_p50_ms,
                f.response_time_p99_ms,
                f.response_time_max_ms,
            ];
            if !r.into_iter().all(ok_response)
                || !ok_ms(f.busy_ms)
                || f.skipped_ticks > bound(NodeId(i))
            {
                return Err(format!(
                    "node '{}': its executor's figures are impossible in {:.2} s",
                    spec.nodes[i].name,
                    at.as_secs_f64()
                ));
            }
        }
        if x.executors
            .iter()
            .any(|e| !(e.utilization.is_finite() && (0.0..=1.0).contains(&e.utilization)))
        {
            return Err("an executor's utilization is outside [0, 1]".into());
        }
    }
    if spec.process_of(spec.actuator) == process {
        let a = &st.actuator;
        let (p50, p99, max) = a.latency_ms;
        if a.steps > bound(spec.actuator)
            || ![a.mean_latency_ms, p50, p99, max].into_iter().all(ok_ms)
            || !a.final_pole_angle.is_finite()
        {
            return Err(format!(
                "the plant's figures are impossible in {:.2} s ({} steps, latency {:.1}/{:.1}/{:.1} ms, angle {})",
                at.as_secs_f64(),
                a.steps,
                p50,
                p99,
                max,
                a.final_pole_angle
            ));
        }
        if a.estimate.as_ref().is_some_and(|e| !e.plausible(a.steps)) {
            return Err(format!(
                "the estimator's figures are impossible in {} steps",
                a.steps
            ));
        }
    }
    Ok(())
}

/// `dst[i] = src[i]` where both exist.
fn take<T: Clone>(dst: &mut [T], src: &[T], i: usize) {
    if let (Some(d), Some(s)) = (dst.get_mut(i), src.get(i)) {
        d.clone_from(s);
    }
}

/// Launch `cfg`'s graph over its placement, one process per group, and run it once.
/// `say` is told progress lines (the endpoint, processes joining or gone).
///
/// The phases, each in its own module: open the session and follow the graph's keys
/// (here), start the processes (`processes`), admit them until all are ready
/// (`admission`), run (under the virtual clock `virtual_run`, the real one `real_run`),
/// then merge the reports into one summary (here).
///
/// # Errors
/// [`DistError`]: a bad or busy endpoint, a process that does not join (or joins with
/// another graph file), a process that fails before the run.
pub fn launch(
    cfg: &RunConfig,
    opts: &LaunchOptions,
    stop: &StopFlag,
    say: &dyn Fn(&str),
) -> Result<LaunchReport, DistError> {
    cfg.validate()
        .map_err(ratelab_runtime::runcore::RunError::from)?;
    let spec = &cfg.graph;
    check_keys(spec)?;
    let placement = spec.placement();
    let names: Vec<String> = placement.iter().map(|(p, _)| p.clone()).collect();
    let processes = names.clone();
    let creds = &opts.credentials;
    let direct = opts.direct(names.len());
    if creds.graph != spec.name || creds.processes != names {
        return Err(DistError::Usage(format!(
            "the credentials are for graph '{}' with processes {:?}, not '{}' with {names:?}",
            creds.graph, creds.processes, spec.name
        )));
    }
    // Peers refused at the TLS handshake (no credentials of this launch), said in the log.
    let refusals = super::refusals::Refusals::new();
    let (session, endpoint) = listen(spec, opts, direct)?;
    let keys = Keys::new(&spec.name);
    let (_up_sub, up_rx) = hear_processes(&session, &keys)?;
    // What the launcher passes on to each process ([`outbox`]).
    let outboxes = outbox::Outboxes::start(&processes)?;
    let me = Launch {
        cfg,
        opts,
        spec,
        stop,
        robot: spec.process_of(spec.actuator),
        placement,
        names,
        endpoint,
        setup: setup_of(cfg, opts, direct),
        direct,
        hash: super::graph_hash(&opts.graph_bytes),
        private: PrivateDir::new()?,
        link: Link {
            keys: keys.clone(),
            session: session.clone(),
            up: up_rx,
        },
        say_to: say,
        last_join_line: RefCell::new(String::new()),
        refusals: RefCell::new(refusals),
        relays: processes::Relays::default(),
        outboxes: &outboxes,
    };
    let endpoint = me.endpoint.clone();
    me.say(&format!("{LISTENING}{endpoint}"));
    me.say(match direct {
        true => "the processes link to the launcher and to each other directly",
        false => "a star: the processes link to the launcher alone",
    });
    if cfg.clock == ClockKind::Virtual && !spec.restart.is_empty() {
        me.say(&format!(
            "restart = \"on-failure\" ({}) does not apply under the virtual clock: a lockstep cannot take a process back, so a process that fails ends the run",
            spec.restart.keys().cloned().collect::<Vec<_>>().join(", ")
        ));
    }
    if let Some(tx) = &opts.listening {
        let _ = tx.send(endpoint.clone());
    }
    let (_live_sub, gone) = watch_gone(&session, &keys)?;
    // The crossing topics' samples, passed on by each process's outbox ([`outbox`]; dropped
    // when it is full under the real clock only); under the virtual clock every process's
    // tick reports too, to follow the run and hand each process the others' in its turn
    // ([`relay`]). Heard before any process starts.
    // Linked directly, the processes send both to each other, and the launcher passes
    // nothing on.
    let real = cfg.clock == ClockKind::Real;
    let _forwarded = match direct {
        true => Vec::new(),
        false => outbox::forward_topics(&session, &keys, spec, &outboxes, real)?,
    };
    let relaying = (!real)
        .then(|| relay::Relay::start(&session, &keys, spec, (&processes[..], &outboxes), direct))
        .transpose()?;
    let _launcher_token = session
        .liveliness()
        .declare_token(keys.launcher_token())
        .wait()?;
    let mut children = me.start_processes()?;
    let _setup_queryable = serve_setup(&session, &keys, &me.setup)?;
    me.admit_until_ready(&mut children)?;
    if let Some(gate) = &opts.start_gate {
        wait_gate(gate, stop, &mut children)?;
    }
    let start = Instant::now();
    let mut reports: BTreeMap<String, GraphState> = BTreeMap::new();
    let mut wires: Vec<wire::WireLink> = Vec::new();
    // What the processes counted as their figures said: a process started again mid-run
    // (real clock) goes on from it, one that died reads it (either clock).
    let mut carried = Carried::new(spec);
    // The processes killed on request (real clock), with when.
    let mut killed = Vec::new();
    // Under the virtual clock every report is of the run up to its end; under the real
    // clock, up to when it came (`taken_at`).
    let (end, lockstep, taken_at) = match &relaying {
        Some(relaying) => {
            let gathered = (&mut reports, &mut wires, &mut carried);
            let (end, lockstep) = me.run_lockstep(relaying, &gone, start, gathered)?;
            (end, lockstep, BTreeMap::new())
        }
        None => {
            let (end, taken_at) = me.supervise(
                &gone,
                &mut children,
                &mut carried,
                &mut reports,
                &mut wires,
                &mut killed,
            )?;
            (end, None, taken_at)
        }
    };
    let wall = start.elapsed();
    // A process whose report never came (frozen, or gone) is not waited for.
    children.reap(Duration::from_secs(5), |p| !reports.contains_key(p));
    let (metrics, missing) = me.conclude(&end, &mut reports, &taken_at, &carried)?;
    // In the graph's topic order, whichever process reported first.
    wires.sort_by_key(|w| spec.topics.iter().position(|t| t.name == w.topic));
    Ok(LaunchReport {
        metrics,
        end,
        wall,
        endpoint,
        wire: wires,
        missing,
        lockstep,
        killed,
    })
}

/// Answer watchers that ask for the run's settings (`ratelab lab --attach`) on the graph's
/// setup key, for as long as the returned queryable is kept.
///
/// # Errors
/// [`DistError`] when the queryable cannot be declared.
fn serve_setup(
    session: &zenoh::Session,
    keys: &Keys,
    setup: &Setup,
) -> Result<zenoh::query::Queryable<()>, DistError> {
    let setup_json = wire::encode_json(setup);
    Ok(session
        .declare_queryable(keys.setup())
        .callback(move |q| {
            let _ = q.reply(q.key_expr().clone(), setup_json.clone()).wait();
        })
        .wait()?)
}

/// The run's settings as every process of the launch and every watcher is given them.
fn setup_of(cfg: &RunConfig, opts: &LaunchOptions, direct: bool) -> Setup {
    Setup {
        graph_toml: cfg.graph.to_toml(),
        seed: cfg.seed,
        duration_ns: cfg.duration.0,
        clock: cfg.clock,
        policy: opts.policy.clone(),
        faults: cfg.faults.clone(),
        phase_offsets_ns: cfg.phase_offsets.iter().map(|n| n.0).collect(),
        spin_margin_ns: cfg.spin_margin.0,
        rt_priority: cfg.rt_priority,
        ros2_domain: opts.ros2_domain,
        direct,
    }
}

/// What the processes say to the launcher (`ToLauncher`), as it arrives: each from its own
/// key only, since a process speaks for itself ([`super::access`] lets it publish on the key
/// that names it, and a message naming another process is dropped). Keep the subscriber.
fn hear_processes(
    session: &zenoh::Session,
    keys: &Keys,
) -> Result<(zenoh::pubsub::Subscriber<()>, Receiver<ToLauncher>), DistError> {
    // At most this many wait; unbounded so that its slots are allocated as messages
    // queue (a bounded channel allocates and touches every slot at once: 5.8 MB here).
    const MAX_UP: usize = 65_536;
    let (up_tx, up_rx) = crossbeam_channel::unbounded::<ToLauncher>();
    let up_prefix = format!("{}/@up/", keys.prefix());
    let sub = session
        .declare_subscriber(keys.up())
        .callback(move |s| {
            let from = s.key_expr().as_str().strip_prefix(up_prefix.as_str());
            if let Ok(m) = wire::decode_json::<ToLauncher>(&s.payload().to_bytes()) {
                if from == Some(m.process()) && up_tx.len() < MAX_UP {
                    let _ = up_tx.send(m);
                }
            }
        })
        .wait()?;
    Ok((sub, up_rx))
}

/// Processes going away: a process is gone once one of its node tokens
/// (`@node/<process>/<node>`) has stayed withdrawn for [`crate::liveliness::WITHDRAWN_FOR`]
/// (Zenoh may withdraw a live token for a moment as routes change: [`crate::liveliness`]).
/// The subscriber's callback notes; the run's loop asks, and what has settled is said then.
pub(super) struct GoneProcesses {
    withdrawals: Withdrawals,
    /// `<prefix>/@node/`, before a token's process.
    token_prefix: String,
    /// Every process gone so far, in the order they went (a process restarted and gone
    /// again is in it twice), and how many of them [`GoneProcesses::next`] has handed out.
    gone: Mutex<(Vec<String>, usize)>,
}

impl GoneProcesses {
    fn new(keys: &Keys) -> Self {
        Self {
            withdrawals: Withdrawals::new(),
            token_prefix: format!("{}/@node/", keys.prefix()),
            gone: Mutex::default(),
        }
    }

    /// Move the settled withdrawals into the list of the gone: the process a token names.
    fn settle(&self) -> std::sync::MutexGuard<'_, (Vec<String>, usize)> {
        let mut gone = ratelab_runtime::graph::lock(&self.gone);
        for key in self.withdrawals.take_settled() {
            if let Some(p) = key
                .strip_prefix(&self.token_prefix)
                .and_then(|r| r.split('/').next())
            {
                gone.0.push(p.to_string());
            }
        }
        gone
    }

    /// Every process gone so far (under the virtual clock: any of them ends the run).
    pub(super) fn all(&self) -> Vec<String> {
        self.settle().0.clone()
    }

    /// The next process gone since the last call, each withdrawal once (under the real
    /// clock, where a process may be started again and go again).
    pub(super) fn next(&self) -> Option<String> {
        let mut gone = self.settle();
        let (list, taken) = &mut *gone;
        let p = list.get(*taken).cloned();
        *taken += usize::from(p.is_some());
        p
    }
}

/// Watch the processes' node tokens for [`GoneProcesses`]. Keep the subscriber.
fn watch_gone(
    session: &zenoh::Session,
    keys: &Keys,
) -> Result<(zenoh::pubsub::Subscriber<()>, Arc<GoneProcesses>), DistError> {
    let gone = Arc::new(GoneProcesses::new(keys));
    let noted = gone.clone();
    let sub = session
        .liveliness()
        .declare_subscriber(format!("{}/@node/**", keys.prefix()))
        .callback(move |s| noted.withdrawals.note(s.key_expr().as_str(), s.kind()))
        .wait()?;
    Ok((sub, gone))
}

/// Open the launcher's session, the router of the launch (linked directly or not,
/// `direct`): on `--listen` (port 0: a free one), else on ratelab's usual port when it is
/// free (watchers look there), else on any free one. Returns the session and the endpoint
/// it listens on.
fn listen(
    spec: &GraphSpec,
    opts: &LaunchOptions,
    direct: bool,
) -> Result<(zenoh::Session, String), DistError> {
    let access = Access {
        credentials: &opts.credentials,
        role: &Role::Router,
        spec: Some(spec),
    };
    let open = |listen: &[String]| super::open_router(listen, access, direct);
    Ok(match &opts.listen {
        Some(ep) => {
            check_endpoint("--listen", ep, true)?;
            let ep = match ep.rsplit_once(':') {
                Some((host, "0")) => {
                    let h = host.trim_start_matches("tls/");
                    format!("tls/{h}:{}", free_port(h)?)
                }
                _ => ep.clone(),
            };
            (open(std::slice::from_ref(&ep))?, ep)
        }
        None => match open(&[super::DEFAULT_ENDPOINT.to_string()]) {
            Ok(s) => (s, super::DEFAULT_ENDPOINT.to_string()),
            Err(_) => {
                let ep = format!("tls/127.0.0.1:{}", free_port("127.0.0.1")?);
                (open(std::slice::from_ref(&ep))?, ep)
            }
        },
    })
}

/// One launch while it runs: its settings, its processes' names, its link to them and its
/// progress lines. Each phase of [`launch`] is a method of it, in its own module.
struct Launch<'a> {
    cfg: &'a RunConfig,
    opts: &'a LaunchOptions,
    spec: &'a GraphSpec,
    stop: &'a StopFlag,
    /// Each process and its nodes ([`GraphSpec::placement`]).
    placement: Vec<(String, Vec<NodeId>)>,
    /// The processes' names, in placement order.
    names: Vec<String>,
    /// The plant's process (the actuator's): it cannot rejoin, and its going ends the run.
    robot: String,
    /// The endpoint the launcher listens on.
    endpoint: String,
    /// The run's settings, sent in every welcome.
    setup: Setup,
    /// Whether the processes are linked directly ([`LaunchOptions::star`]).
    direct: bool,
    /// The graph file's SHA-256, which every join must match.
    hash: String,
    /// Where each started process's credentials are written, removed with the launch.
    private: PrivateDir,
    link: Link,
    /// Where progress lines go (each also on the graph's log key).
    say_to: &'a dyn Fn(&str),
    /// The last line about a join (not said twice in a row).
    last_join_line: RefCell<String>,
    refusals: RefCell<super::refusals::Refusals>,
    /// The threads passing the started processes' stderr on ([`processes`]): waited for
    /// (briefly) when the launch ends, so a process's last words are not lost.
    relays: processes::Relays,
    /// What the launcher passes on to each process ([`outbox`]): under the real clock each
    /// process's live figures tell its outbox it was heard from ([`outbox::Outbox::answered`]).
    outboxes: &'a outbox::Outboxes,
}

impl Launch<'_> {
    /// A progress line, to `say` and whoever watches (`ratelab lab --attach`).
    fn say(&self, line: &str) {
        (self.say_to)(line);
        let _ = self.link.session.put(self.link.keys.log(), line).wait();
    }

    /// A line about joins, unless it was the last one said: a process told to wait asks
    /// again every 100 ms (`process::BUSY_RETRY`).
    fn say_once(&self, line: String) {
        if *self.last_join_line.borrow() != line {
            self.say(&line);
            *self.last_join_line.borrow_mut() = line;
        }
    }

    /// A refused join, said once.
    fn say_refused(&self, reason: &str) {
        self.say_once(format!("refused a join: {reason}"));
    }

    /// The refused connections since the last line, when a line is due
    /// ([`super::refusals::Refusals::say_due`]).
    fn say_refusals_due(&self) {
        self.refusals.borrow_mut().say_due(&|l| self.say(l));
    }

    /// The run's summary from the processes' `reports` (those whose figures cannot be
    /// true of a run that ended at `end`, or for a report taken later under the real clock
    /// at its `taken_at` run time, are refused and said), `carried` on from processes
    /// started again; published on the graph's ended key for watchers. Returns it and the
    /// processes that did not report.
    ///
    /// # Errors
    /// [`DistError::Peer`] without the plant's process's report (refused, or gone with it).
    fn conclude(
        &self,
        end: &RunEnd,
        reports: &mut BTreeMap<String, GraphState>,
        taken_at: &BTreeMap<String, Nanos>,
        carried: &Carried,
    ) -> Result<(Metrics, Vec<String>), DistError> {
        let spec = self.spec;
        let plant = spec.process_of(spec.actuator);
        let mut plant_refused = None;
        // A report whose figures cannot be is not merged: its process counts as not reporting.
        reports.retain(|p, st| {
            match check_report(spec, p, st, report_time(end, taken_at.get(p).copied())) {
                Ok(()) => true,
                Err(why) => {
                    self.say(&format!("refused the report of process '{p}': {why}"));
                    if *p == plant {
                        plant_refused = Some(why);
                    }
                    false
                }
            }
        });
        let missing: Vec<String> = self
            .names
            .iter()
            .filter(|p| !reports.contains_key(*p))
            .cloned()
            .collect();
        let state = merge_states(spec, reports, carried).ok_or_else(|| {
            DistError::Peer(match (&end.reason, plant_refused) {
                (_, Some(why)) => format!(
                    "process '{plant}' (the actuator's) sent a report that cannot be true ({why}): no summary or metrics.json"
                ),
                // The plant's process died: say so, not just that it did not report.
                (EndReason::NodeFailed { node, message }, None) => format!(
                    "node '{node}' failed at t={:.2}s: {message}; no summary or metrics.json: \
                     the plant's figures went with its process",
                    end.at.as_secs_f64()
                ),
                _ => format!("process '{plant}' (the actuator's) did not report"),
            })
        })?;
        let mut metrics = summarize_state(self.cfg, &state, end);
        metrics.missing_processes.clone_from(&missing);
        // The policy's ticks went with its process: not measured, not 0 (the headline would
        // say "0 policy ticks" of a policy that ran for seconds).
        if let Some(c) = spec.chain {
            if missing.contains(&spec.process_of(c.policy)) {
                metrics.policy_ticks = None;
            }
        }
        let over = wire::RunOver {
            metrics: metrics.clone(),
            end: end.clone(),
        };
        let _ = self
            .link
            .session
            .put(self.link.keys.ended(), wire::encode_json(&over))
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait();
        // Let it leave before the session closes (and the launcher's token with it: a watcher
        // takes a token gone without this word for a launcher that died).
        std::thread::sleep(Duration::from_millis(200));
        Ok((metrics, missing))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A launch is linked directly when the launcher starts its processes, they are at most
    /// `DIRECT_LINKS_MAX`, and `--star` is not given; else a star.
    #[test]
    fn a_small_launch_started_here_is_linked_directly_unless_told_star() {
        let names = ["robot".to_string(), "policy".to_string()];
        let opts = |exe: bool, star: bool| LaunchOptions {
            graph_path: None,
            graph_bytes: Vec::new(),
            listen: None,
            policy: "scripted".into(),
            exe: exe.then(|| Program::this().unwrap()),
            child_stderr: None,
            start_gate: None,
            listening: None,
            pace: None,
            credentials: Credentials::generate("chapter", &names).unwrap(),
            ros2_domain: None,
            kill_processes: Vec::new(),
            star,
        };
        let max = crate::DIRECT_LINKS_MAX;
        assert!(opts(true, false).direct(2));
        assert!(opts(true, false).direct(max));
        assert!(
            !opts(true, false).direct(max + 1),
            "a large launch is a star"
        );
        assert!(!opts(true, true).direct(2), "--star");
        assert!(!opts(false, false).direct(2), "processes started by hand");
    }

    /// A 10 s run of the chapter's graph as process `robot` would report it.
    fn robot_report() -> (GraphSpec, GraphState) {
        let spec = GraphSpec::parse(ratelab_runtime::graph::spec::DEFAULT_GRAPH_TOML, "t").unwrap();
        let obs = ratelab_core::topic::TopicStats {
            published: 501,
            dropped: 0,
            ..Default::default()
        };
        let st = GraphState {
            topics: vec![obs, obs],
            topic_qos: vec![ratelab_core::qos::TopicQos::default(); 2],
            subscriptions: Vec::new(),
            liveliness: vec![(None, ratelab_core::qos::LivelinessStatus::default()); 3],
            rates_hz: vec![50.0; 3],
            ticks: vec![501, 0, 501],
            timing: None,
            exec: None,
            brain: "scripted".into(),
            injected_faults: Vec::new(),
            actuator: ratelab_runtime::summary::ActuatorSummary {
                steps: 501,
                fell_at: None,
                watchdog: None,
                mean_latency_ms: 20.0,
                latency_ms: (20.0, 20.0, 40.0),
                final_pole_angle: 0.01,
                nonfinite_actions: 0,
                estimate: None,
            },
        };
        (spec, st)
    }

    #[test]
    fn a_report_is_merged_only_when_its_figures_could_be_true() {
        let (spec, honest) = robot_report();
        let ten_s = Nanos(10_000_000_000);
        assert_eq!(check_report(&spec, "robot", &honest, ten_s), Ok(()));
        let refused = |f: &dyn Fn(&mut GraphState)| {
            let mut st = honest.clone();
            f(&mut st);
            check_report(&spec, "robot", &st, ten_s).unwrap_err()
        };
        assert!(refused(&|st| st.ticks[0] = 999_999).contains("node 'sensor' ticked 999999 times"));
        assert!(refused(&|st| {
            st.topics.pop();
        })
        .contains("not shaped"));
        assert!(refused(&|st| {
            st.injected_faults
                .push(ratelab_runtime::command::parse_fault("sensor@1").unwrap());
        })
        .contains("not shaped"));
        assert!(refused(&|st| st.actuator.latency_ms.2 = f64::NAN).contains("impossible"));
        assert!(refused(&|st| st.actuator.steps = 424_242).contains("impossible"));
        // /action is held by the robot (its subscriber): 5 published, 6 dropped cannot be.
        assert!(refused(&|st| {
            st.topics[1].published = 5;
            st.topics[1].dropped = 6;
        })
        .contains("topic '/action'"));
        // A policy that publishes twice a tick: 1002 in 10 s at 50 Hz can be true, and so
        // can 10⁴ a tick (what one process counts of a node's burst); more than any
        // sequence number reaches cannot.
        let mut st = honest.clone();
        st.topics[1].published = 1002;
        assert_eq!(check_report(&spec, "robot", &st, ten_s), Ok(()));
        st.topics[1].published = 501 * 10_000;
        st.topics[1].lost = 501 * (10_000 - wire::MAX_SENT_PER_TICK as u64);
        assert_eq!(check_report(&spec, "robot", &st, ten_s), Ok(()));
        assert!(refused(&|st| st.topics[1].published = wire::MAX_SEQ + 1).contains("sends at most"));
        assert!(refused(&|st| st.topics[1].lost = wire::MAX_SEQ + 1).contains("sends at most"));
        // Figures of another process's nodes are not this report's to bound.
        let mut st = honest.clone();
        st.ticks[1] = 999_999;
        assert_eq!(check_report(&spec, "robot", &st, ten_s), Ok(()));
        assert!(check_report(&spec, "policy", &st, ten_s).is_err());
    }

    /// A real-clock run ended at 10 s by another process (a node failed there), whose stop
    /// reached the plant's process 200 ms late on a loaded machine: the plant's 10 ticks
    /// meanwhile cannot be true of a run of 10 s, but are of the 10.2 s by which its report
    /// came. A report taken before the end is bounded by the end.
    #[test]
    fn a_report_that_came_after_the_end_may_count_ticks_up_to_when_it_came() {
        let (spec, mut late) = robot_report();
        late.ticks[0] += 10;
        late.ticks[2] += 10;
        late.actuator.steps += 10;
        let end = RunEnd {
            at: Nanos(10_000_000_000),
            reason: EndReason::NodeFailed {
                node: "policy".into(),
                message: "RuntimeError: gave up".into(),
            },
        };
        assert!(check_report(&spec, "robot", &late, report_time(&end, None)).is_err());
        let came = Nanos(10_200_000_000);
        assert_eq!(report_time(&end, Some(came)), came);
        assert_eq!(
            check_report(&spec, "robot", &late, report_time(&end, Some(came))),
            Ok(())
        );
        assert_eq!(report_time(&end, Some(Nanos(9_000_000_000))), end.at);
    }
}
