//! The launcher (`ratelab launch --processes`): starts one `ratelab node` process per
//! placement group, admits them (the graph file's hash must match), runs the graph (the
//! time authority under the virtual clock; the common start under the real one), stops
//! every process it started, and merges their reports into one `metrics.json`.

use super::credentials::{Credentials, PrivateDir, Role};
use super::lockstep::{check_tick_report, subscribe_reports, TickInbox, HORIZON_PERIODS};
use super::member::LiveStats;
use super::monitor::{Carried, Silence};
use super::wire::{self, Setup, Ticked, ToLauncher, ToMember};
use super::{check_endpoint, check_keys, Access, DistError, Keys, REPLY_TIMEOUT};
use crate::config::{ClockKind, RunConfig};
use crate::graph::spec::{GraphSpec, RestartPolicy, MAX_RESTARTS};
use crate::graph::{NodeId, TopicId};
use crate::metrics::Metrics;
use crate::node::{Flow, Node};
use crate::rate::Rate;
use crate::run::{summarize_state, GraphState};
use crate::scheduler::{EndReason, Event, RunEnd, StopFlag, VirtualScheduler};
use crate::time::Nanos;
use crossbeam_channel::Receiver;
use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

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
    /// The `ratelab` binary to start the placement groups with (`None`: start none, and
    /// wait for them to be started by hand with `ratelab node`).
    pub exe: Option<PathBuf>,
    /// Where the started processes' stderr goes, a line at a time as `PROCESS: LINE` (each
    /// line also published on the graph's log key, [`Keys::log`]); `None`: to the
    /// launcher's own stderr. A lab on the terminal takes them, so that no child writes
    /// over its screen. Lines are cut at [`MAX_STDERR_LINE`] bytes; a line that finds the
    /// channel full is dropped here (give a bounded one: it is on the log key anyway).
    pub child_stderr: Option<crossbeam_channel::Sender<String>>,
    /// The run starts only once this receives (or is told, within [`REPLY_TIMEOUT`]): a
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
    /// and its placement): the launcher is authenticated with its own, and hands each
    /// process it starts that process's alone (a file in a private folder, removed when
    /// the launch ends).
    pub credentials: Credentials,
    /// `--ros2`: each process offers its own nodes to ROS 2 on this domain, the plant's
    /// process `/clock` too (the launcher's program holds the ROS 2 session, and so the
    /// embedded router when none answered, for the launch's length).
    pub ros2_domain: Option<u32>,
}

/// The longest line of a started process's stderr that [`LaunchOptions::child_stderr`]
/// passes on, bytes (the rest of the line is dropped).
pub const MAX_STDERR_LINE: usize = 4096;

/// Pass `child`'s stderr on a line at a time, as `PROCESS: LINE`, to `to` and on the log
/// key, until the child closes it (a thread that ends with the child).
fn pass_stderr(
    process: &str,
    child: &mut Child,
    to: crossbeam_channel::Sender<String>,
    session: zenoh::Session,
    log_key: String,
) {
    use std::io::{BufRead, Read};
    let Some(err) = child.stderr.take() else {
        return;
    };
    let process = process.to_string();
    let _ = std::thread::Builder::new()
        .name(format!("stderr {process}"))
        .spawn(move || {
            let mut r = std::io::BufReader::new(err);
            let mut buf = Vec::new();
            loop {
                buf.clear();
                // Bounded: a line longer than the limit is cut, its rest skipped.
                match r
                    .by_ref()
                    .take(MAX_STDERR_LINE as u64)
                    .read_until(b'\n', &mut buf)
                {
                    Ok(0) | Err(_) => return,
                    Ok(_) => {}
                }
                let cut = buf.last() != Some(&b'\n');
                if cut {
                    let mut rest = Vec::new();
                    loop {
                        rest.clear();
                        match r
                            .by_ref()
                            .take(MAX_STDERR_LINE as u64)
                            .read_until(b'\n', &mut rest)
                        {
                            Ok(0) | Err(_) => break,
                            Ok(_) if rest.last() == Some(&b'\n') => break,
                            Ok(_) => {}
                        }
                    }
                }
                let text = String::from_utf8_lossy(&buf);
                let line = format!("{process}: {}", wire::printable(text.trim_end()));
                let _ = session.put(log_key.as_str(), line.as_str()).wait();
                let _ = to.try_send(line);
            }
        });
}

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
}

/// What the launcher made of a join.
enum Admission {
    /// Welcomed: it gets the settings.
    Welcomed,
    /// Refused, and told why.
    Refused(String),
    /// Refused: a process of this graph with another graph file (told why).
    OtherGraph(String),
    /// Not yet: a process of that name still runs (its liveliness token has not gone), so
    /// the joining one, started again at once after the last was killed, asks again for a
    /// while (told why; a second copy gives up).
    Busy(String),
    /// Not a join, or from a name no key can answer.
    Ignored,
}

/// The launcher's link to its processes: publishers per process and the reply channel.
struct Link {
    keys: Keys,
    session: zenoh::Session,
    up: Receiver<ToLauncher>,
}

impl Link {
    fn tell(&self, process: &str, m: &ToMember) -> Result<(), DistError> {
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

/// A node as the launcher's scheduler sees it: its name, tie-break rank and rate (it ticks
/// in its process; the launcher only follows the schedule, [`super::lockstep`]).
struct Slot {
    name: String,
    id: NodeId,
    rate: Rate,
}

impl Node for Slot {
    fn name(&self) -> &str {
        &self.name
    }
    fn priority(&self) -> u32 {
        self.id.0 as u32
    }
    fn rate(&self) -> &Rate {
        &self.rate
    }
    fn tick(&mut self, _now: Nanos) -> Flow {
        Flow::Continue // never called: the launcher skips every tick
    }
}

/// What the launcher's wait for one tick's report came to (virtual clock).
enum Awaited {
    /// The report.
    Report(Ticked),
    /// The run cannot go on: why (the node's process is silent, or out of step).
    Failed(String),
    /// A process of the graph is gone (its liveliness token withdrawn): its ticks will not
    /// come, and a tick awaited elsewhere may wait on its messages.
    Gone(String),
    /// Ctrl-C while the tick hung.
    Interrupted,
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

/// The child processes; every one still running is killed when this is dropped.
struct Children(Vec<(String, Child)>);

impl Children {
    /// Wait up to `grace` for each to exit, then kill the rest.
    fn reap(&mut self, grace: Duration) {
        let deadline = Instant::now() + grace;
        for (_, c) in &mut self.0 {
            while Instant::now() < deadline {
                if let Ok(Some(_)) = c.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            if let Ok(None) = c.try_wait() {
                let _ = c.kill();
            }
            let _ = c.wait();
        }
        self.0.clear();
    }

    /// A child that exited: its process name and status.
    fn exited(&mut self) -> Option<(String, String)> {
        for (p, c) in &mut self.0 {
            if let Ok(Some(status)) = c.try_wait() {
                return Some((p.clone(), status.to_string()));
            }
        }
        None
    }
}

impl Drop for Children {
    fn drop(&mut self) {
        for (_, c) in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// Wait for the start gate ([`LaunchOptions::start_gate`]), for up to [`REPLY_TIMEOUT`].
fn wait_gate(
    gate: &Receiver<()>,
    stop: &StopFlag,
    children: &mut Children,
) -> Result<(), DistError> {
    let deadline = Instant::now() + REPLY_TIMEOUT;
    loop {
        match gate.recv_timeout(Duration::from_millis(50)) {
            Ok(()) => return Ok(()),
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => {
                return Err(DistError::Peer(
                    "the run's watcher stopped before the run started".into(),
                ))
            }
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
        }
        before_the_run(stop, children)?;
        if Instant::now() >= deadline {
            return Err(DistError::Peer(format!(
                "the run's watcher did not hear from every process within {} s",
                REPLY_TIMEOUT.as_secs()
            )));
        }
    }
}

/// Nothing has ended the launch before its run: not Ctrl-C, not a started process that
/// exited.
fn before_the_run(stop: &StopFlag, children: &mut Children) -> Result<(), DistError> {
    if stop.is_stopped() {
        return Err(DistError::Peer("interrupted before the run started".into()));
    }
    if let Some((p, status)) = children.exited() {
        return Err(DistError::Peer(format!(
            "process '{p}' exited ({status}) before the run started"
        )));
    }
    Ok(())
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
/// each topic's from its [holder](crate::graph::spec::TopicSpec::holder)'s process (its
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
            let mut c = carried.total(i).unwrap_or(crate::topic::TopicStats {
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
) -> Option<crate::executor::ExecFigures> {
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
    Some(crate::executor::ExecFigures { nodes, executors })
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
        // A node may publish several times a tick; a process sends at most so many of them.
        let most = bound(topic.publisher).saturating_mul(wire::MAX_SENT_PER_TICK as u64);
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
        let late_ms = run_ms + crate::executor::MAX_COMPUTE.as_millis_f64();
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
/// # Errors
/// [`DistError`]: a bad or busy endpoint, a process that does not join (or joins with
/// another graph file), a process that fails before the run.
pub fn launch(
    cfg: &RunConfig,
    opts: &LaunchOptions,
    stop: &StopFlag,
    say: &dyn Fn(&str),
) -> Result<LaunchReport, DistError> {
    cfg.validate().map_err(crate::run::RunError::from)?;
    let spec = &cfg.graph;
    check_keys(spec)?;
    let placement = spec.placement();
    let names: Vec<String> = placement.iter().map(|(p, _)| p.clone()).collect();
    let creds = &opts.credentials;
    if creds.graph != spec.name || creds.processes != names {
        return Err(DistError::Usage(format!(
            "the credentials are for graph '{}' with processes {:?}, not '{}' with {names:?}",
            creds.graph, creds.processes, spec.name
        )));
    }
    let access = Access {
        credentials: creds,
        role: &Role::Launcher,
        spec: Some(spec),
    };
    let open_session =
        |listen: &[String], connect: &[String]| super::open_session(listen, connect, access);
    // Peers refused at the TLS handshake (no credentials of this launch), said in the log.
    let mut refusals = super::refusals::Refusals::new();
    let (session, endpoint) = match &opts.listen {
        Some(ep) => {
            check_endpoint("--listen", ep, true)?;
            let ep = match ep.rsplit_once(':') {
                Some((host, "0")) => {
                    let h = host.trim_start_matches("tls/");
                    format!("tls/{h}:{}", free_port(h)?)
                }
                _ => ep.clone(),
            };
            (open_session(std::slice::from_ref(&ep), &[])?, ep)
        }
        // Zenoh's usual port when it is free (watchers look there), else any free one.
        None => match open_session(&[super::DEFAULT_ENDPOINT.to_string()], &[]) {
            Ok(s) => (s, super::DEFAULT_ENDPOINT.to_string()),
            Err(_) => {
                let ep = format!("tls/127.0.0.1:{}", free_port("127.0.0.1")?);
                (open_session(std::slice::from_ref(&ep), &[])?, ep)
            }
        },
    };
    let keys = Keys::new(&spec.name);
    // Every progress line also goes to whoever watches (`ratelab lab --attach`).
    let say = |line: &str| {
        say(line);
        let _ = session.put(keys.log(), line).wait();
    };
    say(&format!("listening on {endpoint}"));
    if cfg.clock == ClockKind::Virtual && !spec.restart.is_empty() {
        say(&format!(
            "restart = \"on-failure\" ({}) does not apply under the virtual clock: a lockstep cannot take a process back, so a process that fails ends the run",
            spec.restart.keys().cloned().collect::<Vec<_>>().join(", ")
        ));
    }
    // A process told to wait asks again every 100 ms (`member::BUSY_RETRY`): a line about
    // joins is not said twice in a row.
    let last_join_line = std::cell::RefCell::new(String::new());
    let say_once = |line: String| {
        if *last_join_line.borrow() != line {
            say(&line);
            *last_join_line.borrow_mut() = line;
        }
    };
    let say_refused = |r: &str| say_once(format!("refused a join: {r}"));
    if let Some(tx) = &opts.listening {
        let _ = tx.send(endpoint.clone());
    }
    let (up_tx, up_rx) = crossbeam_channel::bounded::<ToLauncher>(65_536);
    let up_prefix = format!("{}/@up/", keys.prefix());
    let _up_sub = session
        .declare_subscriber(keys.up())
        .callback(move |s| {
            // A process speaks for itself only: the key it may publish on ([`super::access`])
            // names it, and a message naming another process is dropped.
            let from = s.key_expr().as_str().strip_prefix(up_prefix.as_str());
            if let Ok(m) = wire::decode_json::<ToLauncher>(&s.payload().to_bytes()) {
                if from == Some(m.process()) {
                    let _ = up_tx.try_send(m);
                }
            }
        })
        .wait()?;
    // Processes going away: their node tokens are withdrawn.
    let (gone_tx, gone_rx) = crossbeam_channel::unbounded::<String>();
    let gone_now: Arc<Mutex<Vec<String>>> = Arc::default();
    let gone_cb = gone_now.clone();
    let token_prefix = format!("{}/@node/", keys.prefix());
    let _live_sub = session
        .liveliness()
        .declare_subscriber(format!("{}/@node/**", keys.prefix()))
        .callback(move |s| {
            if s.kind() == zenoh::sample::SampleKind::Delete {
                let k = s.key_expr().as_str();
                if let Some(p) = k
                    .strip_prefix(&token_prefix)
                    .and_then(|r| r.split('/').next())
                {
                    crate::graph::lock(&gone_cb).push(p.to_string());
                    let _ = gone_tx.send(p.to_string());
                }
            }
        })
        .wait()?;
    // Virtual clock: every process's tick reports, to follow the run ([`super::lockstep`]).
    let (_ticked_sub, ticked_rx) = subscribe_reports(&session, &keys, None)?;
    let _launcher_token = session
        .liveliness()
        .declare_token(keys.launcher_token())
        .wait()?;
    let mut children = Children(Vec::new());
    // Each started process's credentials, its identity alone, in a folder of this user's
    // that goes with the launch.
    let private = PrivateDir::new()?;
    // Start (or start again) process `p`, with its own credentials.
    let start_process = |p: &str| -> Result<Option<Child>, DistError> {
        let Some(exe) = &opts.exe else {
            return Ok(None);
        };
        // Read by the process at its start; a restart writes it anew.
        let own = private.write(p, &creds.only(&Role::Process(p.to_string()))?)?;
        let mut cmd = Command::new(exe);
        cmd.arg("node").arg("--credentials").arg(&own);
        if let Some(g) = &opts.graph_path {
            cmd.arg("--graph").arg(g);
        }
        // Its own process group: a Ctrl-C at the terminal reaches the launcher only,
        // which then stops every process in order (their reports are merged).
        use std::os::unix::process::CommandExt as _;
        cmd.args(["--process", p, "--connect", &endpoint])
            .process_group(0)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(if opts.child_stderr.is_some() {
                Stdio::piped()
            } else {
                Stdio::inherit()
            });
        // A node dies with the launcher, however the launcher ends.
        // SAFETY: prctl is async-signal-safe and touches only this (child) process.
        unsafe {
            cmd.pre_exec(|| {
                libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM);
                Ok(())
            });
        }
        let mut child = cmd
            .spawn()
            .map_err(|e| DistError::Usage(format!("cannot start {}: {e}", exe.display())))?;
        if let Some(to) = &opts.child_stderr {
            pass_stderr(p, &mut child, to.clone(), session.clone(), keys.log());
        }
        Ok(Some(child))
    };
    if opts.exe.is_some() {
        for (p, _) in &placement {
            if let Some(child) = start_process(p)? {
                children.0.push((p.clone(), child));
            }
        }
    } else {
        say(&format!(
            "waiting for {} to join: ratelab node{} --process NAME --connect {endpoint} --credentials FILE (launch --export-credentials FILE)",
            placement
                .iter()
                .map(|(p, _)| p.as_str())
                .collect::<Vec<_>>()
                .join(", "),
            opts.graph_path
                .as_ref()
                .map_or(String::new(), |g| format!(" --graph {}", g.display()))
        ));
    }
    let link = Link {
        keys: keys.clone(),
        session: session.clone(),
        up: up_rx,
    };
    let hash = super::graph_hash(&opts.graph_bytes);
    let setup = Setup {
        graph_toml: spec.to_toml(),
        seed: cfg.seed,
        duration_ns: cfg.duration.0,
        clock: cfg.clock,
        policy: opts.policy.clone(),
        faults: cfg.faults.clone(),
        phase_offsets_ns: cfg.phase_offsets.iter().map(|n| n.0).collect(),
        spin_margin_ns: cfg.spin_margin.0,
        rt_priority: cfg.rt_priority,
        ros2_domain: opts.ros2_domain,
    };
    // Watchers ask for the run's settings here (`ratelab lab --attach`).
    let setup_json = wire::encode_json(&setup);
    let _setup_queryable = session
        .declare_queryable(keys.setup())
        .callback(move |q| {
            let _ = q.reply(q.key_expr().clone(), setup_json.clone()).wait();
        })
        .wait()?;
    // Admission: each process joins with the graph file's hash, then reports ready. Nothing
    // a joiner sends can end the run: a bad join is refused to that joiner alone.
    let robot = spec.process_of(spec.actuator);
    let admit = |m: &ToLauncher, running: bool, gone: &[String], joined: &[String]| -> Admission {
        let ToLauncher::Join {
            process,
            graph_sha256,
            ..
        } = m
        else {
            return Admission::Ignored;
        };
        if !crate::graph::spec::valid_node_name(process) {
            return Admission::Ignored; // no key to answer on
        }
        let tell_refusal = |reason: String, busy: bool| {
            let _ = link.tell(
                process,
                &ToMember::Reject {
                    reason: reason.clone(),
                    busy,
                },
            );
            Admission::Refused(reason)
        };
        let refuse = |reason: String| tell_refusal(reason, false);
        if !names.contains(process) {
            return refuse(format!(
                "graph '{}' has no process '{process}' (its processes: {})",
                spec.name,
                names.join(", ")
            ));
        }
        let well_formed =
            graph_sha256.len() == 64 && graph_sha256.bytes().all(|b| b.is_ascii_hexdigit());
        if !well_formed {
            return refuse(format!("process '{process}' sent a malformed join"));
        }
        if *graph_sha256 != hash {
            let theirs: String = graph_sha256.chars().take(12).collect();
            let reason = format!(
                "process '{process}' was given a different graph file than the launcher (SHA-256 {theirs}… against {}…)",
                &hash[..12]
            );
            let _ = refuse(reason.clone());
            return Admission::OtherGraph(reason);
        }
        if running {
            if cfg.clock == ClockKind::Virtual {
                return refuse(format!("process '{process}' cannot rejoin: under the virtual clock the run is in lockstep (rejoining works under the real clock)"));
            }
            if *process == robot {
                return refuse(format!("process '{process}' cannot rejoin: it holds the plant, whose state died with it"));
            }
            if !gone.contains(process) {
                let reason = format!("process '{process}' is already running in this graph");
                let _ = tell_refusal(reason.clone(), true);
                return Admission::Busy(reason);
            }
        } else if joined.contains(process) {
            return refuse(format!("process '{process}' has already joined this graph"));
        }
        let _ = link.tell(
            process,
            &ToMember::Welcome {
                setup: Box::new(setup.clone()),
                launcher_mono_ns: wire::mono_now_ns(),
            },
        );
        Admission::Welcomed
    };
    let mut joined = Vec::new();
    let mut ready = Vec::new();
    let deadline = Instant::now()
        + if opts.exe.is_some() {
            REPLY_TIMEOUT
        } else {
            Duration::from_secs(3600)
        };
    while ready.len() < names.len() {
        before_the_run(stop, &mut children)?;
        if Instant::now() >= deadline {
            let missing: Vec<&str> = names
                .iter()
                .filter(|p| !ready.contains(*p))
                .map(String::as_str)
                .collect();
            return Err(DistError::Peer(format!(
                "process(es) {} did not become ready within {} s",
                missing.join(", "),
                REPLY_TIMEOUT.as_secs()
            )));
        }
        refusals.say_due(&say);
        match link.recv(Duration::from_millis(50)) {
            Some(m @ ToLauncher::Join { .. }) => match admit(&m, false, &[], &joined) {
                Admission::Welcomed => joined.push(m.process().to_string()),
                // Before the run, a process with another graph file is the user's mistake.
                Admission::OtherGraph(r) => {
                    std::thread::sleep(Duration::from_millis(300)); // let the refusal reach it
                    return Err(DistError::Usage(r));
                }
                Admission::Refused(r) | Admission::Busy(r) => say_refused(&r),
                Admission::Ignored => {}
            },
            Some(ToLauncher::Ready { process })
                if joined.contains(&process) && !ready.contains(&process) =>
            {
                say(&format!("process '{process}' ready"));
                ready.push(process);
            }
            _ => {}
        }
    }
    if let Some(gate) = &opts.start_gate {
        wait_gate(gate, stop, &mut children)?;
    }
    let start = Instant::now();
    let mut reports: BTreeMap<String, GraphState> = BTreeMap::new();
    let mut wires: Vec<wire::WireLink> = Vec::new();
    // What a process started again mid-run counted before (real clock only).
    let mut carried = Carried::new(spec);
    let mut lockstep = None;
    let end = match cfg.clock {
        ClockKind::Virtual => {
            let slots = spec
                .nodes
                .iter()
                .enumerate()
                .map(|(i, n)| {
                    Ok(Box::new(Slot {
                        name: n.name.clone(),
                        id: NodeId(i),
                        rate: Rate::new(n.rate_hz)?,
                    }) as Box<dyn Node>)
                })
                .collect::<Result<Vec<_>, crate::rate::InvalidRate>>()
                .map_err(|e| DistError::Usage(e.to_string()))?;
            // The whole graph's plan: its events are the processes' reports, in order.
            let mut sched = VirtualScheduler::with_plan(
                &slots,
                &cfg.phase_offsets,
                spec.execution_plan(),
                false,
            );
            let lookahead = slots
                .iter()
                .map(|n| n.rate().period().0)
                .min()
                .unwrap_or(1)
                .saturating_mul(HORIZON_PERIODS);
            let mut inbox = TickInbox::new();
            // No process ticks before the first horizon: anything already here is not a report.
            while ticked_rx.try_recv().is_ok() {}
            let mut published: Vec<Option<u64>> = vec![None; spec.topics.len()];
            let mut horizon: Option<u64> = None;
            // Events (ticks' starts, and their outputs going out after a compute time), the
            // ticks among them, and the instants they fell on.
            let (mut index, mut started, mut instants) = (0u64, 0u64, 0u64);
            let mut last_t = None;
            let failed = |i: usize, at: Nanos, message: String| RunEnd {
                at,
                reason: EndReason::NodeFailed {
                    node: spec.nodes[i].name.clone(),
                    message,
                },
            };
            let paced_from = Instant::now();
            let end = loop {
                let Some(event) = sched.next_event_until(cfg.duration) else {
                    break RunEnd {
                        at: cfg.duration,
                        reason: EndReason::Duration,
                    };
                };
                let (i, t) = event.node_at();
                // Paced: no instant before its wall time (the horizon follows).
                if let Some(speed) = opts.pace.filter(|s| *s > 0.0 && s.is_finite()) {
                    let due = paced_from + Duration::from_secs_f64(t.as_secs_f64() / speed);
                    while !stop.is_stopped() && Instant::now() < due {
                        let left = due.saturating_duration_since(Instant::now());
                        std::thread::sleep(left.min(Duration::from_millis(50)));
                    }
                }
                refusals.say_due(&say);
                // Move the horizon on before the processes reach it; an interrupt stops it.
                let want = t.0.saturating_add(lookahead).min(cfg.duration.0);
                let low = horizon.is_none_or(|h| h < t.0.saturating_add(lookahead / 2));
                if !stop.is_stopped() && low && horizon.is_none_or(|h| want > h) {
                    for p in &names {
                        link.tell(p, &ToMember::Horizon { until_ns: want })?;
                    }
                    horizon = Some(want);
                }
                if horizon.is_none_or(|h| t.0 > h) {
                    // Only after an interrupt: every tick up to the horizon was seen.
                    break RunEnd {
                        at: sched.now(),
                        reason: EndReason::Interrupted,
                    };
                }
                // The tick's report, from its node's process.
                let process = spec.process_of(NodeId(i));
                // Longer than a process waits for an input message itself, so that its
                // own, more precise error comes first.
                let patience = 2 * REPLY_TIMEOUT;
                let deadline = Instant::now() + patience;
                let mut interrupted_at: Option<Instant> = None;
                let report = loop {
                    // Reports already here count before a process's going (it may have
                    // reported, then died).
                    let mut overflow = None;
                    while let Ok(m) = ticked_rx.try_recv() {
                        if let Err(e) = inbox.accept(m, spec) {
                            overflow = Some(e.to_string());
                            break;
                        }
                    }
                    if let Some(e) = overflow {
                        break Awaited::Failed(e);
                    }
                    if let Some(m) = inbox.take(index) {
                        break Awaited::Report(m);
                    }
                    // Any of the graph's processes, not only this tick's: a tick of another
                    // process may be waiting for the gone one's message, and would only
                    // time out (REPLY_TIMEOUT) before saying so.
                    let gone = crate::graph::lock(&gone_now)
                        .iter()
                        .find(|p| names.contains(p))
                        .cloned();
                    if let Some(p) = gone {
                        break Awaited::Gone(p);
                    }
                    if Instant::now() >= deadline {
                        break Awaited::Failed(format!(
                            "process '{process}' did not answer within {} s",
                            patience.as_secs()
                        ));
                    }
                    // Ctrl-C while a tick hangs: a second's grace, then the run ends here.
                    if stop.is_stopped() {
                        let since = *interrupted_at.get_or_insert_with(Instant::now);
                        if since.elapsed() >= Duration::from_secs(1) {
                            break Awaited::Interrupted;
                        }
                    }
                    crossbeam_channel::select! {
                        recv(ticked_rx) -> m => if let Ok(m) = m {
                            if let Err(e) = inbox.accept(m, spec) {
                                break Awaited::Failed(e.to_string());
                            }
                        },
                        recv(link.up) -> m => match m {
                            // Nobody joins a run in lockstep: say so to whoever tries.
                            Ok(m @ ToLauncher::Join { .. }) => match admit(&m, true, &[], &[]) {
                                Admission::Refused(r)
                                | Admission::OtherGraph(r)
                                | Admission::Busy(r) => say_refused(&r),
                                Admission::Welcomed | Admission::Ignored => {}
                            },
                            Ok(_) => {}
                            Err(_) => break Awaited::Failed("the launcher's channel closed".into()),
                        },
                        default(Duration::from_millis(50)) => {}
                    }
                };
                let m = match report {
                    Awaited::Report(m) => m,
                    Awaited::Interrupted => {
                        break RunEnd {
                            at: sched.now(),
                            reason: EndReason::Interrupted,
                        }
                    }
                    Awaited::Failed(message) => break failed(i, t, message),
                    Awaited::Gone(p) => {
                        // The failed node is the gone process's (its first), not the awaited one.
                        let node = placement
                            .iter()
                            .find(|(name, _)| *name == p)
                            .and_then(|(_, ids)| ids.first().map(|n| n.0))
                            .unwrap_or(i);
                        break failed(node, t, format!("process '{p}' is gone"));
                    }
                };
                let compute = match check_tick_report(&m, index, event, spec) {
                    Ok(c) => c,
                    Err(message) => break failed(i, t, message),
                };
                if let Event::Start { .. } = event {
                    sched.start_elsewhere(&slots, i, compute);
                    started += 1;
                }
                index += 1;
                if last_t != Some(t) {
                    instants += 1;
                    last_t = Some(t);
                }
                for &(topic, seq) in &m.published {
                    // Only a topic the node publishes (a report is untrusted input).
                    if spec.nodes[i].publishes.contains(&TopicId(topic)) {
                        published[topic] = Some(seq);
                    }
                }
                if let Some(message) = m.failed {
                    break failed(i, t, message);
                }
                if m.stop {
                    break RunEnd {
                        at: t,
                        reason: EndReason::NodeStopped,
                    };
                }
            };
            // Paced, the wall time is the pace's, not the lockstep's cost.
            lockstep = opts.pace.is_none().then(|| LockstepCost {
                ticks: started,
                instants,
                us_per_instant: start.elapsed().as_secs_f64() * 1e6 / instants.max(1) as f64,
            });
            // Every message sent is delivered before the reports: the last ones too.
            let need: Vec<(usize, u64)> = published
                .iter()
                .enumerate()
                .filter_map(|(t, s)| s.map(|s| (t, s)))
                .collect();
            collect_reports(
                &link,
                &names,
                &gone_now,
                &end,
                need,
                &mut reports,
                &mut wires,
            );
            end
        }
        ClockKind::Real => {
            // Every process's figures: when they stop, the process is silent; of the
            // processes that may be started again (all but the plant's), what one counted
            // before it was killed is carried into the summary, as the lab carries it
            // ([`Carried`]).
            let (stats_tx, stats_rx) = crossbeam_channel::bounded::<LiveStats>(1024);
            let mut _stats_subs = Vec::new();
            for p in &names {
                let tx = stats_tx.clone();
                _stats_subs.push(
                    session
                        .declare_subscriber(keys.stats(p))
                        .callback(move |s| {
                            if let Some(m) = LiveStats::from_sample(&s) {
                                let _ = tx.try_send(m);
                            }
                        })
                        .wait()?,
                );
            }
            let start_mono = wire::mono_now_ns() + 300_000_000;
            for p in &names {
                link.tell(
                    p,
                    &ToMember::Start {
                        start_mono_ns: start_mono,
                    },
                )?;
            }
            let run_time = || Nanos(wire::mono_now_ns().saturating_sub(start_mono));
            let mut end: Option<RunEnd> = None;
            let mut ended: Vec<String> = Vec::new();
            let mut stop_sent = false;
            let mut gone: Vec<String> = Vec::new();
            let mut rejoining: Vec<String> = Vec::new();
            // When each process that rejoined did (its last time): its wire figures count
            // from then.
            let mut rejoined_at: BTreeMap<String, Nanos> = BTreeMap::new();
            // Joins told to wait (their process's last run still had its token), taken
            // again the moment that run is seen gone rather than at the joiner's next ask
            // (100 ms later), when the joiner still asks: it asked within the last 300 ms
            // and its process still runs (a rejoin under the real clock is on this host).
            let mut waiting_join: BTreeMap<String, (Instant, ToLauncher)> = BTreeMap::new();
            // The OS process each rejoining process was let in as: its ask that crossed the
            // welcome is not another copy's.
            let mut welcomed_pid: BTreeMap<String, u32> = BTreeMap::new();
            // Restarts per process ([`RestartPolicy::OnFailure`]), and those given up on.
            let mut restarts: BTreeMap<String, u32> = BTreeMap::new();
            let mut given_up: Vec<String> = Vec::new();
            // When each process's figures last came, and those said to be silent.
            let mut silence = Silence::default();
            let mut silent: Vec<String> = Vec::new();
            loop {
                for m in stats_rx.try_iter() {
                    silence.heard(&m);
                    if let Some(i) = silent.iter().position(|p| *p == m.process) {
                        silent.remove(i);
                        say(&format!("process '{}' is heard again", m.process));
                    }
                    if m.process != robot {
                        carried.see(spec, &m);
                    }
                }
                // A process whose figures stopped while its tokens live: frozen (SIGSTOP),
                // starved or cut off, said long before Zenoh's lease declares it gone.
                for (p, quiet) in silence.silent() {
                    if end.is_none() && !gone.contains(&p) && !silent.contains(&p) {
                        say(&format!(
                            "process '{p}' is silent at t={:.2}s: no figures for {:.1} s while its tokens live (stopped, starved or cut off?); it is gone if Zenoh's lease (10 s) runs out",
                            run_time().as_secs_f64(),
                            quiet.as_secs_f64()
                        ));
                        silent.push(p);
                    }
                }
                // A started process that failed mid-run starts again where the graph says
                // so (not the plant's: the plant went with it).
                if end.is_none() && !stop.is_stopped() {
                    for (p, child) in &mut children.0 {
                        let Ok(Some(status)) = child.try_wait() else {
                            continue;
                        };
                        if status.success()
                            || *p == robot
                            || spec.restart.get(p.as_str()) != Some(&RestartPolicy::OnFailure)
                            || given_up.contains(p)
                        {
                            continue;
                        }
                        let n = restarts.entry(p.clone()).or_insert(0);
                        if *n >= MAX_RESTARTS {
                            say(&format!(
                                "process '{p}' failed again ({status}): not started again (restarted {MAX_RESTARTS} times already)"
                            ));
                            given_up.push(p.clone());
                            continue;
                        }
                        *n += 1;
                        match start_process(p) {
                            Ok(Some(c)) => {
                                say(&format!(
                                    "process '{p}' failed ({status}) at t={:.2}s: starting it again (restart = \"on-failure\", {} of {MAX_RESTARTS})",
                                    run_time().as_secs_f64(),
                                    *n
                                ));
                                *child = c;
                            }
                            Ok(None) => {}
                            Err(e) => {
                                say(&format!(
                                    "process '{p}' failed ({status}); cannot start it again: {e}"
                                ));
                                given_up.push(p.clone());
                            }
                        }
                    }
                }
                while let Ok(p) = gone_rx.try_recv() {
                    if end.is_none()
                        && names.contains(&p)
                        && !ended.contains(&p)
                        && !gone.contains(&p)
                    {
                        gone.push(p.clone());
                        if p == robot {
                            // The plant died with it: the run cannot go on.
                            end = Some(RunEnd {
                                at: run_time().min(cfg.duration),
                                reason: EndReason::NodeFailed {
                                    node: spec.node(spec.actuator).name.clone(),
                                    message: format!("process '{p}' (the plant's) is gone"),
                                },
                            });
                        }
                        let then = if p == robot {
                            "the run ends with it (the plant's)"
                        } else {
                            "the others run on"
                        };
                        say(&format!(
                            "process '{p}' is gone at t={:.2}s (its liveliness token was withdrawn); {then}",
                            run_time().as_secs_f64()
                        ));
                    }
                }
                if stop.is_stopped() && end.is_none() {
                    end = Some(RunEnd {
                        at: run_time().min(cfg.duration),
                        reason: EndReason::Interrupted,
                    });
                }
                if let (Some(e), false) = (&end, stop_sent) {
                    for p in &names {
                        let _ = link.tell(
                            p,
                            &ToMember::Stop {
                                at_ns: e.at.0,
                                need: Vec::new(),
                            },
                        );
                    }
                    stop_sent = true;
                }
                refusals.say_due(&say);
                waiting_join.retain(|_, (asked, m)| {
                    let pid = match m {
                        ToLauncher::Join { pid, .. } => *pid,
                        _ => 0,
                    };
                    asked.elapsed() < Duration::from_millis(300) && crate::procs::process_alive(pid)
                });
                let last_run_gone = waiting_join.keys().find(|p| gone.contains(*p)).cloned();
                let next = match last_run_gone.and_then(|p| waiting_join.remove(&p)) {
                    Some((_, join)) => Some(join),
                    None => link.recv(Duration::from_millis(50)),
                };
                match next {
                    // The ask of one just let in that crossed its welcome: already answered.
                    Some(ToLauncher::Join { process, pid, .. })
                        if rejoining.contains(&process)
                            && welcomed_pid.get(&process) == Some(&pid) => {}
                    // A process restarted mid-run rejoins on the same clock.
                    Some(m @ ToLauncher::Join { .. }) if end.is_none() => {
                        match admit(&m, true, &gone, &[]) {
                            Admission::Welcomed => {
                                if let ToLauncher::Join { pid, .. } = &m {
                                    welcomed_pid.insert(m.process().to_string(), *pid);
                                }
                                gone.retain(|g| g != m.process());
                                rejoined_at.insert(m.process().to_string(), run_time());
                                rejoining.push(m.process().to_string());
                                say(&format!("process '{}' rejoined", m.process()));
                            }
                            Admission::Refused(r) | Admission::OtherGraph(r) => say_refused(&r),
                            // Started again before its last run's token went: it asks again.
                            Admission::Busy(_) => {
                                say_once(format!(
                                    "process '{}' asks to rejoin before its last run's liveliness token went: it is let in once that goes (a second copy gives up)",
                                    m.process()
                                ));
                                waiting_join.insert(m.process().to_string(), (Instant::now(), m));
                            }
                            Admission::Ignored => {}
                        }
                    }
                    Some(ToLauncher::Ready { process })
                        if end.is_none() && rejoining.contains(&process) =>
                    {
                        rejoining.retain(|p| *p != process);
                        link.tell(
                            &process,
                            &ToMember::Start {
                                start_mono_ns: start_mono,
                            },
                        )?;
                    }
                    Some(ToLauncher::Ended { process, end: e }) => {
                        ended.push(process);
                        if e.reason != EndReason::Duration && end.is_none() {
                            end = Some(e);
                        }
                    }
                    Some(ToLauncher::Report {
                        process,
                        state,
                        wire,
                    }) => {
                        wires.retain(|w| w.process != process);
                        let since = rejoined_at.get(&process).map(|t| t.0);
                        wires.extend(wire.into_iter().map(|w| wire::WireLink {
                            since_ns: since,
                            ..w
                        }));
                        reports.insert(process, *state);
                    }
                    _ => {}
                }
                // Every process has reported, or is gone for good.
                let settled = |p: &String| {
                    reports.contains_key(p) || (gone.contains(p) && !rejoining.contains(p))
                };
                if names.iter().all(settled) {
                    break;
                }
                let grace = Nanos::from(REPLY_TIMEOUT);
                let over = run_time() > cfg.duration + grace
                    || stop_sent && run_time() > end.as_ref().map_or(Nanos::ZERO, |e| e.at) + grace;
                if over {
                    break;
                }
            }
            for m in stats_rx.try_iter().filter(|m| m.process != robot) {
                carried.see(spec, &m);
            }
            end.unwrap_or(RunEnd {
                at: cfg.duration,
                reason: EndReason::Duration,
            })
        }
    };
    let wall = start.elapsed();
    children.reap(Duration::from_secs(5));
    // A report whose figures cannot be is not merged: its process counts as not reporting.
    reports.retain(|p, st| match check_report(spec, p, st, end.at) {
        Ok(()) => true,
        Err(why) => {
            say(&format!("refused the report of process '{p}': {why}"));
            false
        }
    });
    let missing: Vec<String> = names
        .iter()
        .filter(|p| !reports.contains_key(*p))
        .cloned()
        .collect();
    let state = merge_states(spec, &reports, &carried).ok_or_else(|| {
        let plant = spec.process_of(spec.actuator);
        DistError::Peer(match &end.reason {
            // The plant's process died: say so, not just that it did not report.
            EndReason::NodeFailed { node, message } => format!(
                "node '{node}' failed at t={:.2}s: {message}; no summary or metrics.json: \
                 the plant's figures went with its process",
                end.at.as_secs_f64()
            ),
            _ => format!("process '{plant}' (the actuator's) did not report"),
        })
    })?;
    let mut metrics = summarize_state(cfg, &state, &end);
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
    let _ = session
        .put(keys.ended(), wire::encode_json(&over))
        .congestion_control(zenoh::qos::CongestionControl::Block)
        .wait();
    // Let it leave before the session closes (and the launcher's token with it: a watcher
    // takes a token gone without this word for a launcher that died).
    std::thread::sleep(Duration::from_millis(200));
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
    })
}

/// Stop every process at `end` and gather its report.
fn collect_reports(
    link: &Link,
    names: &[String],
    gone: &Mutex<Vec<String>>,
    end: &RunEnd,
    need: Vec<(usize, u64)>,
    reports: &mut BTreeMap<String, GraphState>,
    wires: &mut Vec<wire::WireLink>,
) {
    for p in names {
        let _ = link.tell(
            p,
            &ToMember::Stop {
                at_ns: end.at.0,
                need: need.clone(),
            },
        );
    }
    // After Ctrl-C (maybe with a tick hung) the reports get a short while only.
    let patience = if end.reason == EndReason::Interrupted {
        Duration::from_secs(2)
    } else {
        REPLY_TIMEOUT
    };
    let deadline = Instant::now() + patience;
    // A process that is gone (its tokens withdrawn) will not report: no wait for it.
    let waiting = |reports: &BTreeMap<String, GraphState>| {
        let gone = crate::graph::lock(gone);
        names
            .iter()
            .any(|p| !reports.contains_key(p) && !gone.contains(p))
    };
    while Instant::now() < deadline && waiting(reports) {
        if let Some(ToLauncher::Report {
            process,
            state,
            wire,
        }) = link.recv(Duration::from_millis(50))
        {
            wires.extend(wire);
            reports.insert(process, *state);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 s run of the chapter's graph as process `robot` would report it.
    fn robot_report() -> (GraphSpec, GraphState) {
        let spec = GraphSpec::parse(crate::graph::spec::DEFAULT_GRAPH_TOML, "t").unwrap();
        let obs = crate::topic::TopicStats {
            published: 501,
            dropped: 0,
            ..Default::default()
        };
        let st = GraphState {
            topics: vec![obs, obs],
            topic_qos: vec![crate::qos::TopicQos::default(); 2],
            subscriptions: Vec::new(),
            liveliness: vec![(None, crate::qos::LivelinessStatus::default()); 3],
            rates_hz: vec![50.0; 3],
            ticks: vec![501, 0, 501],
            timing: None,
            exec: None,
            brain: "scripted".into(),
            actuator: crate::run::ActuatorSummary {
                steps: 501,
                fell_at: None,
                watchdog: None,
                mean_latency_ms: 20.0,
                latency_ms: (20.0, 20.0, 40.0),
                final_pole_angle: 0.01,
                nonfinite_actions: 0,
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
        assert!(refused(&|st| st.actuator.latency_ms.2 = f64::NAN).contains("impossible"));
        assert!(refused(&|st| st.actuator.steps = 424_242).contains("impossible"));
        // /action is held by the robot (its subscriber): 5 published, 6 dropped cannot be.
        assert!(refused(&|st| {
            st.topics[1].published = 5;
            st.topics[1].dropped = 6;
        })
        .contains("topic '/action'"));
        // A policy that publishes twice a tick: 1002 in 10 s at 50 Hz can be true; more than
        // a process sends in the run's ticks cannot.
        let mut st = honest.clone();
        st.topics[1].published = 1002;
        assert_eq!(check_report(&spec, "robot", &st, ten_s), Ok(()));
        assert!(
            refused(&|st| st.topics[1].published = 600 * wire::MAX_SENT_PER_TICK as u64)
                .contains("sends at most")
        );
        // Figures of another process's nodes are not this report's to bound.
        let mut st = honest.clone();
        st.ticks[1] = 999_999;
        assert_eq!(check_report(&spec, "robot", &st, ten_s), Ok(()));
        assert!(check_report(&spec, "policy", &st, ten_s).is_err());
    }

    #[test]
    fn a_child_s_stderr_comes_as_bounded_lines_named_by_its_process() {
        let mut child = Command::new("sh")
            .args([
                "-c",
                "echo 'first line' >&2; head -c 10000 /dev/zero | tr '\\0' x >&2; echo >&2; printf 'last, no newline' >&2",
            ])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("sh runs");
        let creds = Credentials::generate("g", &[]).expect("credentials");
        let access = Access {
            credentials: &creds,
            role: &Role::Launcher,
            spec: None,
        };
        let session = super::super::open_session(&[super::super::LOOPBACK_ANY.into()], &[], access)
            .expect("a session");
        let (tx, rx) = crossbeam_channel::unbounded();
        pass_stderr("policy", &mut child, tx, session, Keys::new("g").log());
        let _ = child.wait();
        let lines: Vec<String> =
            std::iter::from_fn(|| rx.recv_timeout(Duration::from_secs(5)).ok()).collect();
        assert_eq!(lines.len(), 3, "{lines:?}");
        assert_eq!(lines[0], "policy: first line");
        assert_eq!(lines[1], format!("policy: {}", "x".repeat(MAX_STDERR_LINE)));
        assert_eq!(lines[2], "policy: last, no newline");
    }
}
