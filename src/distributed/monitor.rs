//! Watching a running multi-process graph from outside it: `ratelab lab --attach`, and the
//! lab that `ratelab launch --processes` opens on a terminal.
//!
//! A watcher is one more client of the launcher's router ([`super::open_client`]): it links
//! to the launcher alone, as the processes do. It turns what the graph's processes publish into the
//! lab's own [`Telemetry`], so the one lab (its `App` and `View`) draws a graph in one process
//! and a graph across several alike:
//!
//! - the run's settings ([`Setup`]) come from the launcher, as the answer to a query on
//!   `ratelab/<graph>/@setup` ([`Watch::connect`]);
//! - every process publishes its [`LiveStats`] every [`super::process::STATS_PERIOD`]: the actuator's process
//!   carries its steps (the plant, the sense→act latency), each process its nodes' ticks
//!   (real clock: measured rates and lateness) and the counters of the topics it holds;
//! - a topic's counters live in its subscriber's process (its copy keeps the chapter's buffer
//!   and QoS, `docs/distributed.md`), so each step's counters of a topic held elsewhere are
//!   replaced by the ones the holder sampled after its newest tick no later than the step
//!   ([`Fold::merge_step`]); a step waits until every holder has published figures of its
//!   run time or later ([`Fold::release`]), so those samples are in;
//! - a node is alive while its liveliness token is (`ratelab/<graph>/@node/<process>/<node>`),
//!   as rmw_zenoh tracks its graph; the lab draws one whose token went as NOT ALIVE;
//! - the launcher's progress lines (`@log`) become notices, and its merged summary
//!   (`@ended`, [`RunOver`]) ends the run in the lab.
//!
//! `ratelab_recording::watched::record` writes the same telemetry to a rerun recording
//! (`launch --processes --record`).

use super::credentials::{Credentials, Role};
use super::liveliness::TokenWatch;
use super::process::LiveStats;
use super::wire::{self, RunOver, Setup};
use super::{check_endpoint, open_client, Access, DistError, Keys};
use crossbeam_channel::Sender;
use ratelab_core::runlog::StepRecord;
use ratelab_core::time::Nanos;
use ratelab_core::topic::TopicStats;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::spec::GraphSpec;
use ratelab_runtime::graph::{NodeId, TopicId};
use ratelab_runtime::scheduler::StopFlag;
use ratelab_runtime::telemetry::{Speed, Telemetry};
use std::collections::BTreeMap;
use std::collections::BTreeSet;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How often a watcher sends the lab a status (liveliness, run time).
pub const STATUS_PERIOD: Duration = Duration::from_millis(250);

/// A process whose figures (published every 100 ms) stop for this long while its tokens
/// live is silent: frozen (SIGSTOP), starved, or cut off before Zenoh's lease
/// ([`crate::LinkTimings`]) says it is gone. Its nodes are drawn not alive meanwhile.
pub const SILENT_AFTER: Duration = Duration::from_secs(1);

/// When each process's figures last came, for [`SILENT_AFTER`]: the launcher says a silent
/// process so, a watcher draws its nodes not alive ([`Fold::set_silent`]).
#[derive(Debug, Default)]
pub struct Silence {
    last: BTreeMap<String, Instant>,
}

impl Silence {
    /// Figures `m` came now. A process's last figures ([`LiveStats::done`]) end the watch
    /// on it: it leaves, it is not silent.
    pub fn heard(&mut self, m: &LiveStats) {
        if m.done {
            self.last.remove(&m.process);
        } else {
            self.last.insert(m.process.clone(), Instant::now());
        }
    }

    /// Stop watching `process` (gone, or rejoined as a new process whose figures are yet
    /// to come: its predecessor's silence is not its own).
    pub fn forget(&mut self, process: &str) {
        self.last.remove(process);
    }

    /// The processes silent now, each with how long since its last figures.
    pub fn silent(&self) -> BTreeMap<String, Duration> {
        self.last
            .iter()
            .map(|(p, t)| (p.clone(), t.elapsed()))
            .filter(|(_, quiet)| *quiet >= SILENT_AFTER)
            .collect()
    }
}

/// The plant's steps a watcher holds back at most, waiting for other processes' figures
/// (200 s at 50 Hz; about 1 KB each).
pub const MAX_PENDING_STEPS: usize = 10_000;

/// How long after the run's end a watcher waits for holders' last figures before it hands
/// on the steps still waiting as they are.
pub const OVER_GRACE: Duration = Duration::from_secs(2);

/// The most counter samples a watcher keeps per topic ahead of the steps it shows.
pub const MAX_QUEUED_COUNTERS: usize = 100_000;

/// Events a watcher buffers between Zenoh's callbacks and its fold, at most.
const EVENTS: usize = 64;

/// Folds what a multi-process graph publishes into the lab's [`Telemetry`]: pure, so its
/// rules are unit-tested without a network.
pub struct Fold {
    spec: GraphSpec,
    /// The process holding each topic's counters (its subscriber's, else its publisher's).
    holders: Vec<String>,
    /// Each topic's newest counters from its holder, when the holder is not the plant's,
    /// continued across the holder's restarts.
    carried: Carried,
    /// Per topic held elsewhere, its holder's counters by run time, oldest first, not yet
    /// shown (at most [`MAX_QUEUED_COUNTERS`] per topic; continued across restarts).
    queued: Vec<std::collections::VecDeque<(Nanos, TopicStats)>>,
    /// Per topic held elsewhere, the counters the steps are shown with now: the holder's
    /// newest sample no later than the newest step shown.
    shown: Vec<Option<TopicStats>>,
    /// The process of the actuator, whose steps the lab draws.
    plant: String,
    /// `(process, node)` whose liveliness tokens are alive.
    alive: BTreeSet<(String, String)>,
    /// Processes that said their part of the run is over ([`LiveStats::done`]): their tokens
    /// going is a process leaving, not dying.
    left: BTreeSet<String>,
    /// Processes silent for [`SILENT_AFTER`] or more ([`Fold::set_silent`]).
    silent: BTreeSet<String>,
    /// Liveliness has been heard at least once (before, every node is "unknown").
    heard: bool,
    /// Newest run time seen.
    now: Nanos,
    /// Each node's newest tick handed on, ns (older ones are dropped).
    last_tick: Vec<Option<u64>>,
    /// The plant's steps not yet handed on: each waits until every other process holding a
    /// topic has published figures at least as new (or left, or died), so the counters it is
    /// shown with are not older than it (at most [`MAX_PENDING_STEPS`]).
    pending: std::collections::VecDeque<StepRecord>,
    /// Each process's newest figures' run time.
    reported: std::collections::BTreeMap<String, Nanos>,
    /// The launcher said the run is over: the lab is frozen on it.
    over: bool,
    /// The run's end, handed on once every step before it is ([`Fold::ended`]).
    end: Option<Telemetry>,
    /// The brain's label.
    policy: String,
}

impl Fold {
    /// A fold for the run `cfg` with the brain `policy` (its label in the lab).
    pub fn new(cfg: &RunConfig, policy: &str) -> Fold {
        let spec = cfg.graph.clone();
        let holders = Carried::holders_of(&spec);
        Fold {
            carried: Carried::new(&spec),
            queued: vec![std::collections::VecDeque::new(); spec.topics.len()],
            shown: vec![None; spec.topics.len()],
            plant: spec.process_of(spec.actuator),
            holders,
            spec,
            alive: BTreeSet::new(),
            left: BTreeSet::new(),
            silent: BTreeSet::new(),
            heard: false,
            now: Nanos::ZERO,
            last_tick: vec![None; cfg.graph.nodes.len()],
            pending: std::collections::VecDeque::new(),
            reported: std::collections::BTreeMap::new(),
            over: false,
            end: None,
            policy: policy.to_string(),
        }
    }

    /// `step` (from the actuator's process) with the counters of every topic held by
    /// another process replaced by that holder's at the step's run time (its newest sample
    /// no later than the step; nothing counted yet, or what the processes before it
    /// counted, when all its samples are later; its newest figures when it sent none): the
    /// actuator's process only forwards those topics, so its own copies do not count what
    /// their subscribers do. Steps are merged in run-time order.
    pub fn merge_step(&mut self, step: &StepRecord) -> StepRecord {
        let mut out = step.clone();
        for (i, holder) in self.holders.iter().enumerate() {
            if *holder == self.plant {
                continue;
            }
            while self.queued[i].front().is_some_and(|(t, _)| *t <= step.t) {
                self.shown[i] = self.queued[i].pop_front().map(|(_, s)| s);
            }
            let before_first = self.queued[i].front().map(|(_, first)| {
                // Every sample is later than the step: nothing counted yet by this holder
                // (what the processes before it counted, if any), never its newer counts,
                // which made a total run backwards and a rate read low.
                let none = TopicStats {
                    depth: first.depth,
                    ..TopicStats::default()
                };
                self.carried.continued(i, &none)
            });
            if let Some(s) = self.shown[i].or(before_first).or(self.carried.total(i)) {
                out.topics.set(TopicId(i), s);
            }
        }
        out
    }

    /// One process's figures: the counters it holds, then its ticks and (the plant's
    /// process) its steps as the lab's telemetry. Figures of another graph, or of a process
    /// the graph does not have, are ignored.
    pub fn stats(&mut self, m: LiveStats) -> Vec<Telemetry> {
        let mut out = Vec::new();
        if m.graph != self.spec.name || !self.spec.placement().iter().any(|(p, _)| *p == m.process)
        {
            return out;
        }
        if m.done {
            self.left.insert(m.process.clone());
        } else {
            self.left.remove(&m.process); // a process started again
        }
        if m.process != self.plant {
            self.carried.see(&self.spec, &m);
        }
        for (t_ns, i, st) in &m.counters {
            let ours = self.holders.get(*i).is_some_and(|h| *h == m.process);
            // A sample newer than the figures that carry it is not one.
            if !ours || m.process == self.plant || *t_ns > m.t_ns {
                continue;
            }
            let q = &mut self.queued[*i];
            if q.back().is_some_and(|(t, _)| t.0 > *t_ns) {
                continue; // only forward in time
            }
            if q.len() == MAX_QUEUED_COUNTERS {
                self.shown[*i] = q.pop_front().map(|(_, s)| s);
            }
            q.push_back((Nanos(*t_ns), self.carried.continued(*i, st)));
        }
        if !m.wire.is_empty() {
            let links: Vec<(usize, f64, f64)> = m
                .wire
                .iter()
                .filter_map(|w| {
                    let i = self.spec.topics.iter().position(|t| t.name == w.topic)?;
                    // Only the holder (the subscriber's process) measures its arrivals, and
                    // a link with no sample yet (a process just started again) has no
                    // latency to give (not 0 µs).
                    (self.holders[i] == m.process && w.samples > 0)
                        .then_some((i, w.p50_us, w.p99_us))
                })
                .collect();
            if !links.is_empty() {
                out.push(Telemetry::Wire(links));
            }
        }
        for &(node, now, late, took) in &m.ticks {
            // Only the process's own nodes, and only forward in time.
            let own =
                node < self.spec.nodes.len() && self.spec.process_name(NodeId(node)) == m.process;
            if own && self.last_tick[node] < Some(now) {
                self.last_tick[node] = Some(now);
                out.push(Telemetry::NodeTick {
                    node,
                    now: Nanos(now),
                    lateness: Nanos(late),
                    took: Nanos(took),
                });
            }
        }
        self.reported.insert(m.process.clone(), Nanos(m.t_ns));
        if m.process == self.plant {
            for s in &m.steps {
                if self.pending.len() == MAX_PENDING_STEPS {
                    let s = self.pending.pop_front().expect("full");
                    out.push(Telemetry::Step(Box::new(self.merge_step(&s))));
                }
                self.pending.push_back(s.clone());
            }
        }
        self.now = self.now.max(Nanos(m.t_ns));
        out.extend(self.release());
        out
    }

    /// The plant's steps that may be shown now: those no process holding a topic is behind
    /// (every such process alive and not done has published figures of that run time or
    /// later), with the holders' counters merged in ([`Fold::merge_step`]).
    pub fn release(&mut self) -> Vec<Telemetry> {
        let behind = self
            .holders
            .iter()
            .filter(|p| **p != self.plant && !self.left.contains(*p))
            .filter(|p| {
                // A holder whose nodes' tokens are gone is not waited for.
                !self.heard || self.alive.iter().any(|(ap, _)| ap == *p)
            })
            .map(|p| self.reported.get(p).copied().unwrap_or(Nanos::ZERO))
            .min();
        let mut out = Vec::new();
        while let Some(s) = self.pending.front() {
            // Once the run is over nothing more is waited for.
            if behind.is_some_and(|t| t < s.t) {
                break;
            }
            let s = self.pending.pop_front().expect("a front");
            self.now = self.now.max(s.t);
            out.push(Telemetry::Step(Box::new(self.merge_step(&s))));
        }
        if self.pending.is_empty() {
            out.extend(self.take_end());
        }
        out
    }

    /// Every step still waiting, whatever the holders (they are late: the watch ends, or
    /// the run ended a while ago), then the run's end if it came.
    pub fn flush(&mut self) -> Vec<Telemetry> {
        let mut out = Vec::new();
        while let Some(s) = self.pending.pop_front() {
            self.now = self.now.max(s.t);
            out.push(Telemetry::Step(Box::new(self.merge_step(&s))));
        }
        out.extend(self.take_end());
        out
    }

    /// The status and the run's end, once.
    fn take_end(&mut self) -> Vec<Telemetry> {
        match self.end.take() {
            Some(end) => vec![self.status(), end],
            None => Vec::new(),
        }
    }

    /// A node's liveliness token appeared (`alive`) or was withdrawn. A process that said
    /// its part of the run is over keeps its nodes drawn alive as they leave.
    pub fn liveliness(&mut self, process: &str, node: &str, alive: bool) {
        // Only the graph's own nodes, in their own processes.
        let known = self
            .spec
            .nodes
            .iter()
            .enumerate()
            .any(|(i, n)| n.name == node && self.spec.process_of(NodeId(i)) == process);
        if !known {
            return;
        }
        self.heard = true;
        let key = (process.to_string(), node.to_string());
        if alive {
            self.alive.insert(key);
        } else if !self.left.contains(process) {
            self.alive.remove(&key);
        }
    }

    /// The processes silent now (no figures for [`SILENT_AFTER`] while their tokens
    /// live; the watcher keeps the time). A process that said its part is over is never
    /// silent.
    pub fn set_silent(&mut self, silent: BTreeSet<String>) {
        self.silent = silent.difference(&self.left).cloned().collect();
    }

    /// Is node `id` alive (its token present, its process not silent)? `None` before any
    /// liveliness was heard.
    pub fn is_alive(&self, id: NodeId) -> Option<bool> {
        let process = self.spec.process_of(id);
        self.heard.then(|| {
            !self.silent.contains(&process)
                && self
                    .alive
                    .contains(&(process.clone(), self.spec.node(id).name.clone()))
        })
    }

    /// The run is over (the launcher's word): liveliness is no longer followed (the
    /// processes leaving is not news). The steps still waiting are handed on as their
    /// holders' last figures come (those may arrive after the launcher's word, on other
    /// links), then the status and the merged summary (`Ended`); [`Fold::flush`] hands on
    /// whatever still waits. Returns what can be handed on now.
    pub fn ended(&mut self, over: RunOver) -> Vec<Telemetry> {
        self.over = true;
        self.end = Some(Telemetry::Ended {
            metrics: Box::new(over.metrics),
            reason: over.end.reason,
        });
        // The steps still waiting go first (their holders' last figures may come after
        // the launcher's word, on other links), then the end.
        let out = self.release();
        self.now = self.now.max(over.end.at);
        out
    }

    /// Has the launcher said the run is over?
    pub fn is_over(&self) -> bool {
        self.over
    }

    /// The lab's status now: run time, the settings the run started with (live changes do
    /// not cross processes), each node's liveliness.
    pub fn status(&self) -> Telemetry {
        Telemetry::Status {
            now: self.now,
            paused: false,
            speed: Speed::Times(1.0),
            rates: self.spec.nodes.iter().map(|n| n.rate_hz).collect(),
            depths: self.spec.topics.iter().map(|t| t.depth).collect(),
            qos: self.spec.topics.iter().map(|t| t.qos).collect(),
            alive: (0..self.spec.nodes.len())
                .map(|i| self.is_alive(NodeId(i)))
                .collect(),
            policy: self.policy.clone(),
            exec: None,
            // The steps carry the holders' counters, merged (the figures come in batches).
            topics: None,
        }
    }
}

/// The counters of the topics held by processes that may be started again mid-run (under
/// the real clock), and their nodes' ticks: a process started again (another pid) counts its
/// topics and ticks from zero, so what the ones before it counted, as their last figures
/// said, is carried over and the run's totals go on. The watcher's lab and the launcher's
/// summary both count this way.
#[derive(Clone, Debug)]
pub struct Carried {
    /// The process holding each topic's counters ([`ratelab_runtime::graph::spec::TopicSpec::holder`]).
    holders: Vec<String>,
    /// Each process's OS process id as last heard: a new one is a restart.
    pids: BTreeMap<String, u32>,
    /// Each topic's counters in its holder's newest figures.
    latest: Vec<Option<TopicStats>>,
    /// Per topic, what earlier runs of its holder process counted before it was restarted.
    before: Vec<TopicStats>,
    /// The process running each node.
    node_processes: Vec<String>,
    /// Each node's ticks in its process's newest figures.
    latest_ticks: Vec<Option<u64>>,
    /// Per node, the ticks earlier runs of its process counted before it was restarted.
    before_ticks: Vec<u64>,
    /// The processes heard under two pids or more: their counts are carried over.
    restarted: BTreeSet<String>,
}

impl Carried {
    /// Nothing heard yet, for `spec`'s topics and nodes.
    pub fn new(spec: &GraphSpec) -> Carried {
        let (topics, nodes) = (spec.topics.len(), spec.nodes.len());
        Carried {
            holders: Carried::holders_of(spec),
            pids: BTreeMap::new(),
            latest: vec![None; topics],
            before: vec![TopicStats::default(); topics],
            node_processes: (0..nodes).map(|i| spec.process_of(NodeId(i))).collect(),
            latest_ticks: vec![None; nodes],
            before_ticks: vec![0; nodes],
            restarted: BTreeSet::new(),
        }
    }

    /// The holders of `spec`'s topics (one process name per topic).
    pub fn holders_of(spec: &GraphSpec) -> Vec<String> {
        spec.topics
            .iter()
            .map(|t| spec.process_of(t.holder()))
            .collect()
    }

    /// Take in figures `m` (of a process of `spec`'s graph): a new pid for its process
    /// carries over what the one before counted; its topics' counters become the newest.
    pub fn see(&mut self, spec: &GraphSpec, m: &LiveStats) {
        let restarted = self
            .pids
            .insert(m.process.clone(), m.pid)
            .is_some_and(|pid| pid != m.pid);
        if restarted {
            self.restarted.insert(m.process.clone());
        }
        for i in 0..self.holders.len() {
            if restarted && self.holders[i] == m.process {
                if let Some(last) = self.latest[i].take() {
                    self.before[i] = continued(&self.before[i], &last);
                }
            }
        }
        for (name, st) in &m.topics {
            if let Some(i) = spec.topics.iter().position(|t| t.name == *name) {
                if self.holders[i] == m.process {
                    self.latest[i] = Some(*st);
                }
            }
        }
        for i in 0..self.node_processes.len() {
            if self.node_processes[i] != m.process {
                continue;
            }
            if restarted {
                self.before_ticks[i] += self.latest_ticks[i].take().unwrap_or(0);
            }
            let name = &spec.nodes[i].name;
            if let Some((_, _, _, ticks)) = m.nodes.iter().find(|n| n.0 == *name) {
                self.latest_ticks[i] = Some(*ticks);
            }
        }
    }

    /// Whether `process` was heard restarted (under a second pid): its counts are carried
    /// over from the run before. A process that joined mid-run ([`LiveStats::since_ns`])
    /// and was not heard restarted counts only from its join.
    pub fn saw_restart(&self, process: &str) -> bool {
        self.restarted.contains(process)
    }

    /// Node `i`'s ticks, `now` its process's count, continued from the processes before.
    pub fn node_ticks(&self, i: usize, now: u64) -> u64 {
        now.saturating_add(self.before_ticks.get(i).copied().unwrap_or(0))
    }

    /// Topic `i`'s counters now `now` (its holder's), continued from the processes before.
    pub fn continued(&self, i: usize, now: &TopicStats) -> TopicStats {
        self.before.get(i).map_or(*now, |b| continued(b, now))
    }

    /// Topic `i`'s newest counters, continued; `None` before its holder's first figures.
    pub fn total(&self, i: usize) -> Option<TopicStats> {
        self.latest.get(i)?.map(|l| self.continued(i, &l))
    }
}

/// A restarted holder's counters `now`, continued from what the processes before it counted
/// (`before`): every count added; the newest stamp, the depth and what is in flight are
/// `now`'s.
fn continued(before: &TopicStats, now: &TopicStats) -> TopicStats {
    TopicStats {
        published: before.published.saturating_add(now.published),
        dropped: before.dropped.saturating_add(now.dropped),
        seen: before.seen.saturating_add(now.seen),
        stale_reads: before.stale_reads.saturating_add(now.stale_reads),
        expired: before.expired.saturating_add(now.expired),
        refused: before.refused.saturating_add(now.refused),
        lost: before.lost.saturating_add(now.lost),
        retransmitted: before.retransmitted.saturating_add(now.retransmitted),
        offered_deadline_missed: before
            .offered_deadline_missed
            .saturating_add(now.offered_deadline_missed),
        requested_deadline_missed: before
            .requested_deadline_missed
            .saturating_add(now.requested_deadline_missed),
        ..*now
    }
}

/// What the Zenoh callbacks hand the fold.
enum Event {
    Stats(Box<LiveStats>),
    Alive(String, String, bool),
    /// The launcher's token declared (its withdrawal is read from a [`TokenWatch`]).
    Launcher,
    Log(String),
    Over(Box<RunOver>),
}

/// A watcher connected to a running graph.
pub struct Watch {
    session: zenoh::Session,
    keys: Keys,
    /// The run's settings, as the launcher sent them.
    pub setup: Setup,
    /// The run they describe.
    pub cfg: RunConfig,
    /// The endpoints it connected to.
    pub connect: Vec<String>,
    /// Where this watch is recorded to, if it is (the lab's header shows it).
    pub recording: Option<std::path::PathBuf>,
}

impl Watch {
    /// Connect to `connect` (a launcher's endpoint: its router) as an observer of the
    /// launch whose `credentials` these are, and ask for its graph's settings, for up to
    /// `wait`.
    ///
    /// # Errors
    /// [`DistError::Usage`] for a bad endpoint, or when no graph answers within `wait`
    /// (one line naming the endpoints); [`DistError::Peer`] when `stop` is set meanwhile.
    pub fn connect(
        connect: &[String],
        credentials: &Credentials,
        wait: Duration,
        stop: &StopFlag,
    ) -> Result<Watch, DistError> {
        if connect.is_empty() {
            return Err(DistError::Usage(
                "--connect tls/HOST:PORT is required: a running launcher's endpoint".into(),
            ));
        }
        for ep in connect {
            check_endpoint("--connect", ep, false)?;
        }
        let access = Access {
            credentials,
            role: &Role::Observer,
            spec: None,
        };
        let session = open_client(connect, access)?;
        let selector = Keys::new(&credentials.graph).setup();
        let deadline = Instant::now() + wait;
        loop {
            if let Some(setup) = ask_setup(&session, &selector) {
                let cfg = setup.run_config()?;
                return Ok(Watch {
                    session,
                    keys: Keys::new(&cfg.graph.name),
                    setup,
                    cfg,
                    connect: connect.to_vec(),
                    recording: None,
                });
            }
            if stop.is_stopped() {
                return Err(DistError::Peer("interrupted".into()));
            }
            if Instant::now() >= deadline {
                return Err(DistError::Usage(format!(
                    "no running ratelab graph '{}' answered at {} within {} s",
                    credentials.graph,
                    connect.join(", "),
                    wait.as_secs()
                )));
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Subscribe to what a watcher follows, each turned into an [`Event`] on `ev_tx`: the
    /// processes' figures, their nodes' liveliness, the launcher's, its progress lines and
    /// its word that the run is over. Keep the subscribers.
    fn listen(
        &self,
        ev_tx: Sender<Event>,
        launcher_token: &TokenWatch,
    ) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, DistError> {
        let keys = &self.keys;
        // A full queue drops the event (the fold is behind; Zenoh's threads never wait).
        let send = |tx: &Sender<Event>, e: Event| {
            let _ = tx.try_send(e);
        };
        let t = ev_tx.clone();
        let stats = self
            .session
            .declare_subscriber(keys.stats("*"))
            .callback(move |s| {
                if let Some(m) = LiveStats::from_sample(&s) {
                    send(&t, Event::Stats(Box::new(m)));
                }
            })
            .wait()?;
        let t = ev_tx.clone();
        let prefix = format!("{}/@node/", keys.prefix());
        let nodes = self
            .session
            .liveliness()
            .declare_subscriber(format!("{}/@node/**", keys.prefix()))
            .history(true)
            .callback(move |s| {
                let alive = s.kind() == zenoh::sample::SampleKind::Put;
                let rest = s.key_expr().as_str().strip_prefix(&prefix).unwrap_or("");
                // Names that are not a graph file's (any text can be a Zenoh key) are not ours.
                let named = |x: &str| ratelab_runtime::graph::spec::valid_node_name(x);
                if let Some((p, n)) = rest.split_once('/').filter(|(p, n)| named(p) && named(n)) {
                    // Liveliness is news the fold must not miss: wait a little for room.
                    let e = Event::Alive(p.to_string(), n.to_string(), alive);
                    let _ = t.send_timeout(e, Duration::from_secs(1));
                }
            })
            .wait()?;
        let t = ev_tx.clone();
        let token = launcher_token.clone();
        let launcher = self
            .session
            .liveliness()
            .declare_subscriber(keys.launcher_token())
            .history(true)
            .callback(move |s| {
                token.note(s.kind());
                if s.kind() == zenoh::sample::SampleKind::Put {
                    send(&t, Event::Launcher);
                }
            })
            .wait()?;
        let t = ev_tx.clone();
        let log = self
            .session
            .declare_subscriber(keys.log())
            .callback(move |s| {
                let bytes = s.payload().to_bytes();
                // A progress line, or a process's stderr line (at most MAX_STDERR_LINE
                // bytes, after its process's name): its control characters written out.
                if bytes.len() <= crate::MAX_STDERR_LINE + 256 {
                    let line = String::from_utf8_lossy(&bytes);
                    let first = line.lines().next().unwrap_or("");
                    send(
                        &t,
                        Event::Log(ratelab_core::text::printable(first).into_owned()),
                    );
                }
            })
            .wait()?;
        let t = ev_tx;
        let over = self
            .session
            .declare_subscriber(keys.ended())
            .callback(move |s| {
                if let Ok(m) = wire::decode_json::<RunOver>(&s.payload().to_bytes()) {
                    let _ = t.send_timeout(Event::Over(Box::new(m)), Duration::from_secs(1));
                }
            })
            .wait()?;
        Ok(vec![stats, nodes, launcher, log, over])
    }

    /// Send the lab the run's telemetry until `stop` is set or the lab hangs up (its
    /// receiver is dropped): `Started` at once, then steps, ticks, notices and a status every
    /// [`STATUS_PERIOD`], and `Ended` when the launcher says so; `signals` are told when
    /// the watch covers the run, and when it has had the processes' last figures.
    ///
    /// # Errors
    /// [`DistError::Zenoh`] when a subscription cannot be declared.
    pub fn run(
        self,
        tx: &Sender<Telemetry>,
        stop: &StopFlag,
        signals: Signals,
    ) -> Result<(), DistError> {
        let (ev_tx, ev_rx) = crossbeam_channel::bounded::<Event>(EVENTS);
        // The launcher's token, gone once withdrawn for good ([`crate::liveliness`]).
        let launcher_token = TokenWatch::new();
        let _subscribers = self.listen(ev_tx, &launcher_token)?;
        let mut fold = Fold::new(&self.cfg, &self.setup.policy);
        let started = Telemetry::Started {
            cfg: self.cfg.clone(),
            policy: self.setup.policy.clone(),
            recording: self.recording.clone(),
        };
        if tx.send(started).is_err() {
            return Ok(());
        }
        let mut last_status = Instant::now();
        let mut silence = Silence::default();
        let mut launcher_seen = false;
        let mut over_at: Option<Instant> = None;
        let processes: Vec<String> = self
            .cfg
            .graph
            .placement()
            .into_iter()
            .map(|(p, _)| p)
            .collect();
        // The graph's processes, whose lines on the log key are their nodes' own.
        let names = processes.clone();
        let node_names: Vec<String> = self
            .cfg
            .graph
            .nodes
            .iter()
            .map(|n| n.name.clone())
            .collect();
        let mut pending = Pending {
            signals,
            unheard: processes.clone(),
            unfinished: processes,
            done: BTreeSet::new(),
        };
        while !stop.is_stopped() {
            let mut out = Vec::new();
            let ev = ev_rx.recv_timeout(STATUS_PERIOD / 2);
            if let Ok(e) = &ev {
                pending.note(e);
            }
            if let Ok(Event::Stats(m)) = &ev {
                silence.heard(m);
            }
            fold.set_silent(silence.silent().into_keys().collect());
            match ev {
                Ok(Event::Stats(m)) => out = fold.stats(*m),
                Ok(Event::Alive(p, n, alive)) if !fold.is_over() => {
                    fold.liveliness(&p, &n, alive);
                    out = fold.release();
                    // A status at once: a process started again within a status period
                    // would otherwise leave none in which its nodes were not alive, and
                    // the lab and the recording would not see it go.
                    out.push(fold.status());
                    last_status = Instant::now();
                }
                Ok(Event::Launcher) => launcher_seen = true,
                Ok(Event::Log(line)) => match process_line(&line, &names, &node_names) {
                    // What a process's nodes wrote: to the lab's log pane, stamped as in
                    // one process.
                    Some(l) => {
                        ratelab_core::textlog::emit_for(l.node.as_deref(), l.t, l.level, &l.text)
                    }
                    None => out.push(Telemetry::Applied(format!("launch: {line}"))),
                },
                Ok(Event::Over(over)) if !fold.is_over() => {
                    over_at = Some(Instant::now());
                    out = fold.ended(*over);
                }
                Ok(_) | Err(_) => {}
            }
            if launcher_seen && !fold.is_over() && launcher_token.is_gone() {
                out.push(Telemetry::Error(
                    "the launcher is gone: the run is over (no summary was received)".into(),
                ));
                launcher_seen = false;
            }
            // Holders late with their last figures (or dead at the end) are given a while.
            if over_at.is_some_and(|t| t.elapsed() >= OVER_GRACE) {
                over_at = None;
                out.extend(fold.flush());
            }
            if last_status.elapsed() >= STATUS_PERIOD && !fold.is_over() {
                last_status = Instant::now();
                out.push(fold.status());
            }
            for t in out {
                if tx.send(t).is_err() {
                    return Ok(()); // the lab is gone
                }
            }
        }
        // Stopped: whatever still waits goes out as it is.
        for t in fold.flush() {
            if tx.send(t).is_err() {
                break;
            }
        }
        Ok(())
    }
}

/// What a watcher tells the launch it runs in ([`Watch::run`]).
#[derive(Debug, Default)]
pub struct Signals {
    /// Told once figures have come from every process of the graph's placement: from then
    /// on nothing any process publishes misses this watcher (Zenoh delivers each process's
    /// samples in order, through the router too), so a launcher that waits for it before the run
    /// ([`super::launcher::LaunchOptions`]'s `start_gate`) has the whole run watched.
    pub watching: Option<Sender<()>>,
    /// Told once every process has published its last figures ([`LiveStats::done`]) or
    /// withdrawn its nodes' tokens (it left or died): nothing more is coming.
    pub finished: Option<Sender<()>>,
}

/// A line on the log key that a process of the graph (one of `processes`) wrote on its
/// stderr, `PROCESS: [t=1.234 s node] text` (the launcher passes each on so), read back as
/// the line its node wrote; `None` for the launcher's own progress lines.
fn process_line(
    line: &str,
    processes: &[String],
    nodes: &[String],
) -> Option<ratelab_core::textlog::LogLine> {
    let (process, rest) = line.split_once(": ")?;
    if !processes.iter().any(|p| p == process) {
        return None;
    }
    let mut l =
        ratelab_core::textlog::LogLine::parse_prefixed(rest, ratelab_core::textlog::Level::Info);
    if l.node.as_ref().is_some_and(|n| !nodes.contains(n)) {
        // A stamp naming no node of the graph (`[ratelab] warning: …`): the text's own.
        l.t = None;
        l.node = None;
        l.text = rest.to_string();
    }
    if l.node.is_none() {
        // Not a node's: the process's own (a warning, a failure), said as the process's.
        l.text = format!("{process}: {}", l.text);
    }
    Some(l)
}

/// The processes a watcher's [`Signals`] still wait for.
struct Pending {
    signals: Signals,
    unheard: Vec<String>,
    unfinished: Vec<String>,
    /// Processes that sent their last figures.
    done: BTreeSet<String>,
}

impl Pending {
    fn note(&mut self, e: &Event) {
        match e {
            Event::Stats(m) => {
                self.unheard.retain(|p| *p != m.process);
                if m.done {
                    self.unfinished.retain(|p| *p != m.process);
                }
            }
            Event::Alive(p, _, false) => self.unfinished.retain(|q| q != p),
            // Started again (the real clock): its last figures are to come after all.
            Event::Alive(p, _, true)
                if !self.done.contains(p)
                    && !self.unfinished.contains(p)
                    && self.unheard.is_empty()
                    && self.signals.finished.is_some() =>
            {
                self.unfinished.push(p.clone());
            }
            _ => {}
        }
        if let Event::Stats(m) = e {
            if m.done {
                self.done.insert(m.process.clone());
            }
        }
        if self.unheard.is_empty() {
            if let Some(w) = self.signals.watching.take() {
                let _ = w.send(());
            }
        }
        if self.unfinished.is_empty() {
            if let Some(w) = self.signals.finished.take() {
                let _ = w.send(());
            }
        }
    }
}

/// A process of a running graph, as its launcher placed it.
#[derive(Clone, Debug, PartialEq)]
pub struct PlacedProcess {
    /// Its name.
    pub name: String,
    /// Its nodes: name, kind, rate (Hz).
    pub nodes: Vec<(String, String, f64)>,
    /// The topics whose counters it holds (their subscriber's process, or the publisher's
    /// when nobody subscribes: [`ratelab_runtime::graph::spec::TopicSpec::holder`]), by name.
    pub holds: Vec<String>,
}

/// Ask the launcher of graph `graph` (its name as its keys spell it) for the graph, for up
/// to a second: `ratelab top` lists the processes it has no figures from (a process gone
/// before it started) and their topics from its placement ([`placed_processes`]), and
/// carries a restarted process's counts over ([`Carried`]). `None` when no launcher
/// answers with settings that decode.
pub fn ask_graph(session: &zenoh::Session, graph: &str) -> Option<GraphSpec> {
    let cfg = ask_setup(session, &Keys::new(graph).setup())?
        .run_config()
        .ok()?;
    Some(cfg.graph)
}

/// `spec`'s processes: every process, with its nodes and the topics it holds.
pub fn placed_processes(spec: &GraphSpec) -> Vec<PlacedProcess> {
    spec.placement()
        .into_iter()
        .map(|(name, ids)| PlacedProcess {
            nodes: ids
                .iter()
                .map(|&i| {
                    let n = spec.node(i);
                    (n.name.clone(), n.kind_name().to_string(), n.rate_hz)
                })
                .collect(),
            holds: spec
                .topics
                .iter()
                .filter(|t| ids.contains(&t.holder()))
                .map(|t| t.name.clone())
                .collect(),
            name,
        })
        .collect()
}

/// Ask once (for up to a second) for a graph's settings; the first answer that decodes.
pub(crate) fn ask_setup(session: &zenoh::Session, selector: &str) -> Option<Setup> {
    let replies = session
        .get(selector)
        .timeout(Duration::from_secs(1))
        .wait()
        .ok()?;
    while let Ok(r) = replies.recv() {
        if let Ok(s) = r.result() {
            if let Ok(setup) = wire::decode_json::<Setup>(&s.payload().to_bytes()) {
                return Some(setup);
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::runlog::TopicCounters;

    fn cfg() -> RunConfig {
        RunConfig {
            graph: GraphSpec::chapter(),
            ..RunConfig::default()
        }
    }

    #[test]
    fn a_process_s_stderr_line_is_its_node_s_and_a_progress_line_is_the_launcher_s() {
        let processes = vec!["robot".to_string(), "policy".to_string()];
        let nodes = vec!["sensor".to_string(), "policy".to_string()];
        let l = process_line("policy: [t=1.240 s policy] tick here", &processes, &nodes).unwrap();
        assert_eq!(
            (l.t, l.node.as_deref(), l.text.as_str()),
            (
                Some(ratelab_core::time::Nanos(1_240_000_000)),
                Some("policy"),
                "tick here"
            )
        );
        let own = process_line("robot: warning: something", &processes, &nodes).unwrap();
        assert_eq!(
            (own.node, own.text.as_str()),
            (None, "robot: warning: something")
        );
        let tool = process_line("robot: [ratelab] warning: x", &processes, &nodes).unwrap();
        assert_eq!(
            (tool.node, tool.text.as_str()),
            (None, "robot: [ratelab] warning: x")
        );
        assert!(process_line("process 'policy' joined: 2 of 2", &processes, &nodes).is_none());
        assert!(process_line("elsewhere: [t=1.0 s p] x", &processes, &nodes).is_none());
    }

    fn stats(published: u64, dropped: u64) -> TopicStats {
        TopicStats {
            published,
            dropped,
            depth: 1,
            ..TopicStats::default()
        }
    }

    fn live(process: &str, topics: Vec<(&str, TopicStats)>, steps: Vec<StepRecord>) -> LiveStats {
        LiveStats {
            graph: "cartpole".into(),
            process: process.into(),
            pid: 1,
            t_ns: 0,
            nodes: Vec::new(),
            topics: topics
                .into_iter()
                .map(|(n, s)| (n.to_string(), s))
                .collect(),
            wire: Vec::new(),
            steps,
            ticks: Vec::new(),
            counters: Vec::new(),
            done: false,
            since_ns: None,
        }
    }

    fn step(t_ms: u64, obs: TopicStats, action: TopicStats) -> StepRecord {
        StepRecord {
            step: 1,
            t: Nanos(t_ms * 1_000_000),
            pole_angle: 0.0,
            pole_angvel: 0.0,
            cart_pos: 0.0,
            action: 0.0,
            latency: None,
            held_stamp: None,
            nonfinite: false,
            topics: [obs, action].into_iter().collect::<TopicCounters>(),
            published: None,
            fell: false,
            estimate: None,
        }
    }

    #[test]
    fn a_node_whose_process_is_started_again_goes_on_counting_its_ticks() {
        let spec = cfg().graph;
        let policy = spec.node_id("policy").unwrap().0;
        let sensor = spec.node_id("sensor").unwrap().0;
        let mut carried = Carried::new(&spec);
        let ticking = |pid: u32, process: &str, node: &str, ticks: u64| {
            let mut m = live(process, Vec::new(), Vec::new());
            m.pid = pid;
            m.nodes = vec![(node.into(), node.into(), 50.0, ticks)];
            m
        };
        carried.see(&spec, &ticking(7, "policy", "policy", 100));
        carried.see(&spec, &ticking(7, "policy", "policy", 148));
        carried.see(&spec, &ticking(3, "robot", "sensor", 150));
        // Killed after 148 ticks; started again (another pid), it counts from 0.
        carried.see(&spec, &ticking(9, "policy", "policy", 2));
        assert_eq!(carried.node_ticks(policy, 250), 398);
        // Another process's nodes are untouched; nothing restarted, ticks are as reported.
        assert_eq!(carried.node_ticks(sensor, 400), 400);
        assert_eq!(Carried::new(&spec).node_ticks(policy, 250), 250);
    }

    /// `m` with figures of run time `t_ms`.
    fn at(t_ms: u64, mut m: LiveStats) -> LiveStats {
        m.t_ns = t_ms * 1_000_000;
        m
    }

    #[test]
    fn a_topic_held_by_another_process_takes_its_holders_counters() {
        let mut f = Fold::new(&cfg(), "scripted");
        // The chapter's graph: /obs is read in `policy`, /action in `robot`.
        let obs_at_policy = stats(10, 7);
        let policy = live("policy", vec![("/obs", obs_at_policy)], vec![]);
        assert!(f.stats(at(20, policy)).is_empty());
        // The robot's own copy of /obs only forwards (its counters are not the topic's).
        let out = f.stats(live(
            "robot",
            vec![("/action", stats(2, 0))],
            vec![step(20, stats(10, 9), stats(2, 0))],
        ));
        let [Telemetry::Step(s)] = out.as_slice() else {
            panic!("one step expected, got {}", out.len())
        };
        assert_eq!(s.topics.get(TopicId(0)), obs_at_policy);
        // /action is held by the robot's process itself: its step's figures stand.
        assert_eq!(s.topics.get(TopicId(1)), stats(2, 0));
    }

    #[test]
    fn a_restarted_holder_continues_the_counts_of_the_one_before() {
        let mut f = Fold::new(&cfg(), "scripted");
        f.stats(live("policy", vec![("/obs", stats(100, 3))], vec![]));
        // The policy's process is started again: its copy of /obs counts from zero.
        let mut again = live("policy", vec![("/obs", stats(5, 1))], vec![]);
        again.pid = 2;
        f.stats(again.clone());
        let step = f.merge_step(&step(20, stats(0, 0), stats(0, 0)));
        assert_eq!(step.topics.get(TopicId(0)), stats(105, 4));
        // Later figures of the same process add to the same base.
        again.topics = vec![("/obs".into(), stats(9, 1))];
        f.stats(again);
        let step = f.merge_step(&step_at(40));
        assert_eq!(step.topics.get(TopicId(0)), stats(109, 4));
    }

    fn step_at(t_ms: u64) -> StepRecord {
        step(t_ms, stats(0, 0), stats(0, 0))
    }

    #[test]
    fn each_step_shows_the_counters_its_holder_had_at_the_step_s_run_time() {
        // Under the virtual clock one batch of figures spans seconds of run time: the
        // policy's copy of /obs was sampled after each of its ticks.
        let mut f = Fold::new(&cfg(), "scripted");
        let mut m = at(100, live("policy", vec![("/obs", stats(5, 0))], vec![]));
        let ms = 1_000_000;
        m.counters = vec![(10 * ms, 0, stats(1, 0)), (20 * ms, 0, stats(2, 0))];
        m.counters.push((40 * ms, 0, stats(4, 1)));
        m.counters.push((30 * ms, 0, stats(99, 9))); // back in time: ignored
        f.stats(m);
        let shown: Vec<TopicStats> = [5, 10, 15, 20, 35, 40, 60]
            .iter()
            .map(|t| f.merge_step(&step_at(*t)).topics.get(TopicId(0)))
            .collect();
        assert_eq!(
            shown,
            [
                // Before its first sample: nothing counted yet (its newest figures, 5,
                // then 1 at 10 ms, ran the total backwards).
                stats(0, 0),
                stats(1, 0),
                stats(1, 0),
                stats(2, 0),
                stats(2, 0),
                stats(4, 1),
                stats(4, 1),
            ]
        );
        // Samples from a process that does not hold the topic are not its counters.
        let mut robot = live("robot", vec![], vec![]);
        robot.counters = vec![(70 * ms, 0, stats(50, 0)), (70 * ms, 99, stats(50, 0))];
        f.stats(robot);
        assert_eq!(
            f.merge_step(&step_at(80)).topics.get(TopicId(0)),
            stats(4, 1)
        );
        // Nor is a sample from after the figures that carry it (it would freeze the rest).
        let mut ahead = at(200, live("policy", vec![], vec![]));
        ahead.counters = vec![(10_000 * ms, 0, stats(77, 0)), (150 * ms, 0, stats(6, 1))];
        f.stats(ahead);
        assert_eq!(
            f.merge_step(&step_at(160)).topics.get(TopicId(0)),
            stats(6, 1)
        );
    }

    #[test]
    fn figures_of_another_graph_or_an_unknown_process_are_ignored() {
        let mut f = Fold::new(&cfg(), "scripted");
        let mut other = live("policy", vec![("/obs", stats(5, 5))], vec![]);
        other.graph = "elsewhere".into();
        f.stats(other);
        f.stats(at(
            1000,
            live("intruder", vec![("/obs", stats(6, 6))], vec![]),
        ));
        f.stats(at(1000, live("policy", vec![], vec![])));
        let out = f.stats(live(
            "robot",
            vec![],
            vec![step(20, stats(1, 0), stats(0, 0))],
        ));
        let [Telemetry::Step(s)] = out.as_slice() else {
            panic!("one step expected")
        };
        assert_eq!(s.topics.get(TopicId(0)), stats(1, 0));
        // Steps only come from the actuator's process.
        assert!(f
            .stats(live(
                "policy",
                vec![],
                vec![step(40, stats(1, 0), stats(0, 0))]
            ))
            .is_empty());
    }

    #[test]
    fn a_silent_process_s_nodes_are_not_alive_until_its_figures_come_again() {
        let mut f = Fold::new(&cfg(), "scripted");
        let policy = NodeId(1);
        f.liveliness("policy", "policy", true);
        assert_eq!(f.is_alive(policy), Some(true));
        f.set_silent(BTreeSet::from(["policy".to_string()]));
        assert_eq!(f.is_alive(policy), Some(false));
        assert_eq!(
            f.is_alive(NodeId(0)),
            Some(false),
            "robot's token never came"
        );
        f.set_silent(BTreeSet::new());
        assert_eq!(f.is_alive(policy), Some(true));
    }

    #[test]
    fn a_node_is_alive_while_its_token_is() {
        let mut f = Fold::new(&cfg(), "scripted");
        let policy = NodeId(1);
        assert_eq!(
            f.is_alive(policy),
            None,
            "unknown before any token is heard"
        );
        f.liveliness("robot", "sensor", true);
        f.liveliness("policy", "policy", true);
        assert_eq!(f.is_alive(policy), Some(true));
        f.liveliness("policy", "policy", false);
        assert_eq!(f.is_alive(policy), Some(false));
        // A token of the same name in another process is not this node's.
        f.liveliness("robot", "policy", true);
        assert_eq!(f.is_alive(policy), Some(false));
        let Telemetry::Status { alive, .. } = f.status() else {
            panic!("a status")
        };
        assert_eq!(alive, vec![Some(true), Some(false), Some(false)]);
        // A process whose part of the run is over leaves: its nodes are not drawn dead.
        let mut last = live("robot", vec![], vec![]);
        last.done = true;
        f.stats(last);
        f.liveliness("robot", "sensor", false);
        assert_eq!(f.is_alive(NodeId(0)), Some(true));
        // Started again, it can die again.
        f.stats(live("robot", vec![], vec![]));
        f.liveliness("robot", "sensor", false);
        assert_eq!(f.is_alive(NodeId(0)), Some(false));
    }

    #[test]
    fn the_plants_steps_wait_for_the_holders_figures_of_their_time() {
        let mut f = Fold::new(&cfg(), "scripted");
        let steps = vec![step_at(20), step_at(40), step_at(60)];
        f.stats(at(10, live("policy", vec![("/obs", stats(1, 0))], vec![])));
        assert!(f.stats(at(60, live("robot", vec![], steps))).is_empty());
        // The policy's figures of 40 ms release the steps up to 40 ms, with its counters.
        let out = f.stats(at(40, live("policy", vec![("/obs", stats(3, 1))], vec![])));
        assert_eq!(out.len(), 2);
        let Telemetry::Step(s) = &out[1] else {
            panic!("a step")
        };
        assert_eq!(
            (s.t, s.topics.get(TopicId(0))),
            (Nanos(40_000_000), stats(3, 1))
        );
        // A holder that died is not waited for.
        f.liveliness("robot", "sensor", true);
        f.liveliness("policy", "policy", false);
        let out = f.release();
        assert!(matches!(out.as_slice(), [Telemetry::Step(s)] if s.t == Nanos(60_000_000)));
        // The run's end hands on whatever still waits.
        f.liveliness("policy", "policy", true);
        f.stats(at(80, live("robot", vec![], vec![step_at(80)])));
        assert!(f.release().is_empty());
        let over = RunOver {
            metrics: {
                let mut core = ratelab_runtime::runcore::RunCore::new(
                    &RunConfig {
                        duration: Nanos(20_000_000),
                        clock: crate::ClockKind::Virtual,
                        ..cfg()
                    },
                    Box::new(ratelab_runtime::policy::Scripted),
                    ratelab_runtime::runcore::CoreOptions::default(),
                )
                .unwrap();
                core.run_to_end(&ratelab_runtime::scheduler::StopFlag::default());
                core.metrics()
            },
            end: ratelab_runtime::scheduler::RunEnd {
                at: Nanos(80_000_000),
                reason: ratelab_runtime::scheduler::EndReason::Duration,
            },
        };
        // The run's end waits for the step's holder (its last figures may come after it);
        // a flush hands on the step, the status and the end.
        assert!(f.ended(over).is_empty());
        let out = f.flush();
        assert!(
            matches!(
                out.as_slice(),
                [
                    Telemetry::Step(_),
                    Telemetry::Status { .. },
                    Telemetry::Ended { .. }
                ]
            ),
            "{out:?}"
        );
        assert!(f.flush().is_empty(), "the end goes out once");
    }

    #[test]
    fn wire_latency_is_taken_from_the_receiving_process() {
        let mut f = Fold::new(&cfg(), "scripted");
        let link = |topic: &str, process: &str| wire::WireLink {
            topic: topic.into(),
            process: process.into(),
            samples: 10,
            p50_us: 120.0,
            p99_us: 300.0,
            max_us: 400.0,
            in_place: 0,
            drawn_in_place: 0,
            since_ns: None,
        };
        let mut m = live("policy", vec![], vec![]);
        // /obs arrives in `policy`; a claim about /action from `policy` is not its to make.
        m.wire = vec![link("/obs", "policy"), link("/action", "policy")];
        let out = f.stats(m);
        let [Telemetry::Wire(links)] = out.as_slice() else {
            panic!("one wire report expected")
        };
        assert_eq!(links, &vec![(0, 120.0, 300.0)]);
        // Started again, the policy's process has no sample yet: no latency, not 0 µs.
        let mut m = live("policy", vec![], vec![]);
        m.wire = vec![wire::WireLink {
            samples: 0,
            p50_us: 0.0,
            p99_us: 0.0,
            ..link("/obs", "policy")
        }];
        assert!(f.stats(m).iter().all(|t| !matches!(t, Telemetry::Wire(_))));
    }

    #[test]
    fn ticks_are_taken_only_for_the_senders_own_nodes() {
        let mut f = Fold::new(&cfg(), "scripted");
        let mut m = live("policy", vec![], vec![]);
        m.ticks = vec![
            (1, 20_000_000, 50_000, 7_000),
            (0, 20_000_000, 1, 1),
            (99, 0, 0, 0),
        ];
        let out = f.stats(m.clone());
        assert_eq!(out.len(), 1);
        // A tick no newer than one handed on (a peer replaying, or out of order) is dropped:
        // the lab's rates assume time goes forward.
        m.ticks = vec![(1, 10_000_000, 0, 0), (1, 20_000_000, 0, 0)];
        assert!(f.stats(m).is_empty());
        assert!(matches!(
            out[0],
            Telemetry::NodeTick {
                node: 1,
                lateness: Nanos(50_000),
                took: Nanos(7_000),
                ..
            }
        ));
    }

    #[test]
    fn the_signals_wait_for_every_process_first_and_last() {
        let (w_tx, w_rx) = crossbeam_channel::bounded(1);
        let (f_tx, f_rx) = crossbeam_channel::bounded(1);
        let mut p = Pending {
            signals: Signals {
                watching: Some(w_tx),
                finished: Some(f_tx),
            },
            unheard: vec!["robot".into(), "policy".into()],
            unfinished: vec!["robot".into(), "policy".into()],
            done: BTreeSet::new(),
        };
        p.note(&Event::Stats(Box::new(live("robot", vec![], vec![]))));
        assert!(
            w_rx.try_recv().is_err(),
            "the policy's process is not heard yet"
        );
        p.note(&Event::Stats(Box::new(live("policy", vec![], vec![]))));
        assert!(
            w_rx.try_recv().is_ok(),
            "every process heard: the run may start"
        );
        let mut last = live("robot", vec![], vec![]);
        last.done = true;
        p.note(&Event::Stats(Box::new(last)));
        assert!(
            f_rx.try_recv().is_err(),
            "the policy's last figures are still to come"
        );
        // A process that died sends no last figures: its tokens going is its end.
        p.note(&Event::Alive("policy".into(), "policy".into(), false));
        assert!(f_rx.try_recv().is_ok());
    }
}
