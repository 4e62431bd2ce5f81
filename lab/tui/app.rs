//! The lab's state: folds telemetry from the engine and the user's keys; builds a [`View`]
//! each frame (`app/views.rs`). Keys become engine [`Control`]s; nothing here blocks the
//! graph.

use super::keymap::{depth_down, depth_up, rate_down, rate_up, Msg};
use super::live::Live;
use super::view::{
    Badge, LatencyView, LogView, NavView, NodeView, Ros2View, SegmentView, Selected, TopicView,
    Verdict, View, WindowLatency,
};
use crossbeam_channel::Sender;
use ratelab::config::{check_rate, BREAK_CONTROL_HZ};
use ratelab::executor::{ExecutorKind, ExecutorOverride};
use ratelab::graph::kind::Code;
use ratelab::graph::{GraphSpec, NodeId, TopicId};
use ratelab::plant::GEAR_N;
use ratelab::qos::{Delivery, OnDeadlineMissed, QosCounter, Reliability, TopicQos};
use ratelab::run::Command;
use ratelab::runlog::StepRecord;
use ratelab::scheduler::EndReason;
use ratelab::session::{Control, Speed, Telemetry, SPEEDS};
use ratelab::Nanos;
use std::collections::VecDeque;

mod checkpoints;
mod hang;
mod journal;
mod log;
mod review;
mod scrub;
mod settings;
mod views;
use views::Faults;

/// Told each new run's graph ([`App::on_graph`]): `Some(line)` to say.
pub type GraphHook = Box<dyn Fn(&GraphSpec) -> Option<String> + Send>;

/// Seconds of pole-angle and force history kept at full rate (the widest window short of
/// the whole run, [`super::chart_window::FULL_RATE_S`]).
pub const HISTORY_S: f64 = super::chart_window::FULL_RATE_S;
/// Window for the real clock's measured node rates and tick lateness. (Topics and latency
/// count over [`super::live::WINDOW`] and the segment since the last change.)
pub const TICK_WINDOW: Nanos = Nanos::SECOND;
/// How long a new notice leads the footer (before the keys), wall time.
pub const FRESH: std::time::Duration = std::time::Duration::from_secs(4);
/// Latency histogram bucket width.
pub const BUCKET: Nanos = Nanos(20_000_000);
/// Number of latency buckets shown (the last collects everything above).
pub const BUCKETS: usize = 11;

/// Collects every step record of a run (for [`App::after_virtual_run`]).
struct Collect(std::sync::Arc<std::sync::Mutex<Vec<StepRecord>>>);

impl ratelab::graph::StepObserver for Collect {
    fn on_step(&mut self, r: &StepRecord) {
        self.0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(r.clone());
    }
}

/// A short name for the status line: `scripted`, or the checkpoint's file name.
fn short_brain(spec: &str) -> String {
    std::path::Path::new(spec)
        .file_name()
        .map_or_else(|| spec.to_string(), |f| f.to_string_lossy().into_owned())
}

/// What a key that would change the graph says in an attached lab (a graph across
/// processes, which takes no live changes yet).
pub const READ_ONLY: &str = "read-only: live changes do not cross processes yet";
/// What `b`, `[` and `]` say on a graph without the chapter's chain.
pub const NO_CHAIN: &str =
    "no sensor → policy → actuator chain here: select a node (Tab), then -/+";

/// The deadlines `d` cycles through on the selected topic, ms (0: none; 30 ms is exercise
/// ex5's deadline).
pub const DEADLINES_MS: [f64; 6] = [0.0, 25.0, 30.0, 50.0, 100.0, 200.0];
/// The link losses `L` cycles through on the selected topic (probabilities; 80 % is the
/// loss at which exercise ex5 asks what a reliable link still delivers).
pub const LOSSES: [f64; 6] = [0.0, 0.01, 0.05, 0.2, 0.5, 0.8];
/// The lifespans `l` cycles through on the selected topic, ms (0: none).
pub const LIFESPANS_MS: [f64; 5] = [0.0, 20.0, 50.0, 100.0, 200.0];
/// The phase offsets `P` cycles the selected node (else the policy) through, ms: exercise
/// ex3 gives the chain 0, 5 and 10 (sense, then think 5 ms later, then act 5 ms after that).
pub const PHASES_MS: [f64; 4] = [0.0, 5.0, 10.0, 15.0];

/// The first value of the ascending `cycle` above `now`, or the first of all after the
/// last (a value from a file or flag that is not in the cycle joins it where it fits).
fn next_in_cycle(cycle: &[f64], now: f64) -> f64 {
    cycle
        .iter()
        .copied()
        .find(|&v| v > now + 1e-9)
        .unwrap_or(cycle[0])
}

/// A latency in ms to its tenth, rounded down from the exact sample: 199.9996 ms reads
/// `199.9`, as the bar it is counted in (`<200`) says, never `200.0`; 200 ms exactly reads
/// `200.0`.
fn tenth_ms_down(n: Nanos) -> f64 {
    (n.0 / 100_000) as f64 / 10.0
}

/// A QoS counter as the lab's edges label it.
fn short_counter(c: QosCounter) -> &'static str {
    match c {
        QosCounter::Expired => "expired",
        QosCounter::Refused => "refused",
        QosCounter::Lost => "lost",
        QosCounter::Retransmitted => "retx",
        QosCounter::OfferedDeadlineMissed => "dl miss (pub)",
        QosCounter::RequestedDeadlineMissed => "dl miss",
    }
}

/// The lab's state.
pub struct App {
    tx: Sender<Control>,
    clock: String,
    speed: Speed,
    paused: bool,
    now: Nanos,
    seed: u64,
    brain: String,
    policy_spec: String,
    alt_policy: Option<String>,
    recording: Option<String>,
    /// The running graph's shape.
    graph: GraphSpec,
    /// Each node's set rate, by node index.
    rates: Vec<f64>,
    /// Rates asked for and not yet seen in a status, by node index: the rate and the run
    /// time when asked. A status the engine sent before it took the command still carries
    /// the old rate; taking it would make the next key step from the old rate (a burst of
    /// `-` lost a step under load). Kept until a status shows the rate, or for
    /// [`PENDING_RATE`] of run time (a refused rate then gives way to the engine's).
    pending_rates: Vec<Option<(f64, ratelab::Nanos)>>,
    /// Each topic's depth, by topic index.
    depths: Vec<usize>,
    /// Each topic's QoS, by topic index.
    qos: Vec<TopicQos>,
    /// Each node's phase offset, ms, by node index: the run's `--phase-offset-ms`, then the
    /// phase changes the engine made (`P`, a replayed `set_phase`).
    phases: Vec<f64>,
    /// The reliable topics whose losses this run has explained (once each, in the footer).
    explained_losses: Vec<TopicId>,
    /// Each topic's first step seen reliable since it was last made so, and its losses
    /// counted before it (by topic index; `None` while it is best effort): losses under
    /// best effort are not explained as reliable delivery's.
    lost_before_reliable: Vec<Option<(ratelab::Nanos, u64)>>,
    /// Each topic's losses at the last step folded, by topic index.
    lost_at_last_step: Vec<u64>,
    /// Each node's liveliness, by node index (`None`: no lease).
    alive: Vec<Option<bool>>,
    /// The run's injected faults: given at the start (`--stall`, `--kill`) and injected
    /// while it goes (`k`).
    faults: Faults,
    /// Virtual clock with executors: each node's ticks and skipped ticks, as counted at the
    /// run times they come with, over the arrows' window ([`super::live::WINDOW`]) and the
    /// count just before it.
    exec: VecDeque<(Nanos, Vec<(u64, u64)>)>,
    /// What Tab selected.
    selected: Option<Selected>,
    /// The graph panel's zoom, scroll and filter.
    nav: super::navigate::Navigation,
    /// The window (last 5 s) and the segment since the last change.
    live: Live,
    history: VecDeque<(f64, f64)>,
    /// The whole run's angle and applied force, thinned (the charts' widest window).
    thinned: super::chart_window::Thinned,
    /// With an estimator in the graph: its estimate's lines and figures, step by step
    /// ([`super::estimates`]).
    estimates: super::estimates::Estimates,
    /// The charts' time window (`(` / `)`).
    chart_window: super::chart_window::ChartWindow,
    /// Reviewing an ended real-clock run ([`review`]).
    review: Option<review::Review>,
    /// Told each new run's graph (the lab's file watch follows it); returns what to say
    /// when it cannot.
    on_graph: Option<GraphHook>,
    /// (t s, applied force N) per actuator step over the last [`HISTORY_S`].
    applied: VecDeque<(f64, f64)>,
    /// (t s, published force N) per policy publication seen over the last [`HISTORY_S`].
    published: VecDeque<(f64, f64)>,
    ticks: Vec<VecDeque<(Nanos, Nanos, Nanos)>>,
    /// The ticks of the last second, for the executor timeline ([`super::timeline`]).
    timeline: super::timeline::Timeline,
    /// The timeline shown in place of the latency histogram (key `t`).
    show_timeline: bool,
    /// What nodes' code and ratelab's warnings wrote ([`ratelab::textlog`]), the newest
    /// [`LOG_LINES`], and where they come from while the lab runs.
    log: VecDeque<ratelab::textlog::LogLine>,
    log_rx: Option<crossbeam_channel::Receiver<ratelab::textlog::LogLine>>,
    /// Lines received in all (the pane says how many it holds of them).
    log_total: usize,
    /// The log pane shown in place of the latency histogram (key `v`).
    show_log: bool,
    /// How far the pane is scrolled back from the newest line, lines (PgUp / PgDn): its
    /// selected entry.
    log_back: usize,
    /// The line shown whole over the lab (Enter), by its number among all received.
    log_open: Option<usize>,
    /// Rows of the line shown whole scrolled past (PgUp / PgDn while it is shown).
    log_scroll: usize,
    /// The folder paths in the log pane are shown relative to (the graph file's).
    code_folder: Option<String>,
    /// When Ctrl-C last interrupted a hung callback (a second one quits).
    interrupted_at: Option<std::time::Instant>,
    /// The ROS 2 domain the graph is offered on (`--ros2`), if it is.
    ros2_domain: Option<u32>,
    /// The graph panel shows the graph as ROS 2 sees it (key `g`).
    show_ros2: bool,
    /// Under the real clock, the executors `x` asked for, for the next run (its threads are
    /// made when a run starts): the timeline keeps drawing the ones that run.
    pending_executor: Option<&'static str>,
    /// The run time of the last change of settings (the executors' counts before it are
    /// dropped, so a node's rate and skipped ticks never average over two settings).
    exec_from: Option<Nanos>,
    /// The rates and depths the run ended with (after a fall the keys set the next run's,
    /// and the frozen figures stay beside the settings they were measured under).
    ended_with: Option<(Vec<f64>, Vec<usize>, Vec<TopicQos>)>,
    /// Attached to a launch, once it ended: each topic's totals as its summary gives them
    /// (the launcher's accounting, which counts what a gone process's copy no longer can).
    final_topics: Option<std::collections::BTreeMap<String, ratelab::metrics::TopicMetrics>>,
    last: Option<StepRecord>,
    verdict: Verdict,
    help: bool,
    /// Esc was pressed with nothing open to close: one more Esc quits (any other key stays).
    confirm_quit: bool,
    typing: Option<String>,
    message: Option<String>,
    /// When the message was set (a fresh one leads the footer for [`FRESH`]).
    message_at: Option<std::time::Instant>,
    /// The run time the last seek back went to: while its notice is the message, the notice
    /// names where the run is now ([`App::shown_message`]: a step or a seek from there moves
    /// the run on).
    back_at: Option<Nanos>,
    /// Watching a graph that runs across processes (`ratelab lab --attach`): the header's
    /// note (`2 processes`); keys that would change the graph are refused.
    attached: Option<String>,
    /// What the run told since it started, each with the run time the lab was at after it:
    /// folded again up to a seek's instant to show the run as it was then.
    journal: Vec<(Nanos, Telemetry)>,
    /// About how many bytes the journal holds ([`Telemetry::approx_bytes`]).
    journal_bytes: usize,
    /// The journal reached [`MAX_JOURNAL`] or [`MAX_JOURNAL_BYTES`] and stopped.
    journal_full: bool,
    /// The lab's folded view every so many journal messages: a seek back folds from the
    /// nearest ([`checkpoints`]).
    checkpoints: checkpoints::Checkpoints,
    /// (t s, θ rad, applied force N, sense→act latency) of the run's first [`GHOST_S`] of
    /// run time: the ghost of the next run when a saved file is reloaded.
    whole: Vec<GhostStep>,
    /// The run before a reload, drawn dim beside this one ([`Telemetry::Reloaded`]).
    ghost: Vec<GhostStep>,
    /// A reload was said (its line): the next run's start keeps this one as its ghost, and
    /// says the line again (a start clears what was said about the run before).
    reloading: Option<String>,
    /// The reload line of the run on screen, when it runs code just saved: said again when
    /// it ends, its end going to the status bar ([`App::ended_word`]).
    run_reload: Option<String>,
    /// How the run on screen ended, for the status bar, while its reload line holds the
    /// footer.
    ended_word: Option<String>,
    /// A seek back is folding the journal again (its start is not a new run).
    rewinding: bool,
    /// Where the last seek sent asked the engine to put the run, and how many seeks it has
    /// not answered yet ([`Telemetry::Sought`]): while any is out, a burst of ← moves a step
    /// per key, each from the one before, not all from the cursor the screen still shows.
    seek_target: Option<(Nanos, usize)>,
    /// Attached: the launch's endpoint.
    endpoint: Option<String>,
    /// Attached: each topic's over-the-wire latency (p50, p99 µs) when it crosses processes.
    wire: Vec<Option<(f64, f64)>>,
    /// Set when the user asked to quit.
    pub quit: bool,
}

/// How much of a run is kept as the ghost of the next, s of run time (a save usually comes
/// within seconds of watching a run; 3 000 steps at 50 Hz).
pub const GHOST_S: f64 = 60.0;

/// One actuator step of a run kept as a ghost: (t s, θ rad, applied force N, its sense→act
/// latency, `None` when it applied no command).
pub type GhostStep = (f64, f64, f64, Option<Nanos>);

impl App {
    /// A lab sending controls on `tx`. `policy` is the starting brain spec and `alt_policy`
    /// the checkpoint the `p` key swaps with `scripted`.
    pub fn new(
        tx: Sender<Control>,
        policy: String,
        alt_policy: Option<String>,
        speed: Speed,
    ) -> Self {
        Self {
            tx,
            clock: String::new(),
            speed,
            paused: false,
            now: Nanos::ZERO,
            seed: 0,
            brain: String::new(),
            policy_spec: policy,
            alt_policy,
            recording: None,
            graph: GraphSpec::chapter(),
            rates: Vec::new(),
            pending_rates: Vec::new(),
            depths: Vec::new(),
            qos: Vec::new(),
            phases: Vec::new(),
            explained_losses: Vec::new(),
            lost_before_reliable: Vec::new(),
            lost_at_last_step: Vec::new(),
            alive: Vec::new(),
            faults: Faults::default(),
            exec: VecDeque::new(),
            selected: None,
            nav: super::navigate::Navigation::default(),
            live: Live::default(),
            history: VecDeque::new(),
            estimates: Default::default(),
            thinned: Default::default(),
            chart_window: Default::default(),
            review: None,
            on_graph: None,
            applied: VecDeque::new(),
            published: VecDeque::new(),
            ticks: Vec::new(),
            timeline: Default::default(),
            show_timeline: false,
            log: VecDeque::new(),
            log_rx: None,
            log_total: 0,
            show_log: false,
            log_back: 0,
            log_open: None,
            log_scroll: 0,
            code_folder: None,
            interrupted_at: None,
            ros2_domain: None,
            show_ros2: false,
            pending_executor: None,
            exec_from: None,
            ended_with: None,
            final_topics: None,
            last: None,
            verdict: Verdict::Balanced,
            help: false,
            typing: None,
            message: None,
            message_at: None,
            back_at: None,
            confirm_quit: false,
            attached: None,
            journal: Vec::new(),
            journal_bytes: 0,
            journal_full: false,
            checkpoints: Default::default(),
            whole: Vec::new(),
            ghost: Vec::new(),
            reloading: None,
            run_reload: None,
            ended_word: None,
            rewinding: false,
            seek_target: None,
            endpoint: None,
            wire: Vec::new(),
            quit: false,
        }
    }

    /// Take the run's text log from `rx` ([`ratelab::textlog`]): the pane (key `v`) shows it.
    pub fn take_log(&mut self, rx: crossbeam_channel::Receiver<ratelab::textlog::LogLine>) {
        self.log_rx = Some(rx);
    }

    /// Move the lines that came into the log (the newest [`LOG_LINES`] are kept).
    pub fn drain_log(&mut self) {
        let Some(rx) = &self.log_rx else {
            return;
        };
        for line in rx.try_iter() {
            self.log_total += 1;
            if self.log.len() == LOG_LINES {
                self.log.pop_front();
            }
            self.log.push_back(line);
        }
    }

    /// The failed node's line (`policy: FILE:LINE: …`) when the run on screen ended with a
    /// node that failed: the lab then exits 2 saying so, after restoring the terminal.
    pub fn failed_node(&self) -> Option<&str> {
        match &self.verdict {
            Verdict::Failed(line) => Some(line),
            _ => None,
        }
    }

    /// Tell `hook` each new run's graph (not the journal's runs folded again).
    pub fn on_graph(&mut self, hook: GraphHook) {
        self.on_graph = Some(hook);
    }

    /// Draw `spec` until the run's first telemetry says more (the lab knows its graph before
    /// the run starts; without this the first frames show the chapter's).
    pub fn show_graph(&mut self, spec: GraphSpec) {
        self.graph = spec;
    }

    /// Name `clock` in the header until the run's first telemetry says more: a run whose
    /// start is held (a node's script loading that never returns) still says its clock.
    pub fn show_clock(&mut self, clock: ratelab::ClockKind) {
        self.clock = clock.to_string();
    }

    /// The graph is offered to ROS 2 on `domain` (`--ros2`): key `g` shows it as ROS 2 sees
    /// it.
    pub fn set_ros2_domain(&mut self, domain: u32) {
        self.ros2_domain = Some(domain);
    }

    /// Mark the lab as watching a graph across processes; `label` (`2 processes`) joins the
    /// header and each node box names its process.
    pub fn set_attached(&mut self, label: String) {
        self.attached = Some(label);
    }

    /// Attached: where the launch listens, for the footer.
    pub fn set_endpoint(&mut self, endpoint: Option<String>) {
        self.endpoint = endpoint;
    }

    /// A lab (scripted brain) fed with the telemetry of one deterministic virtual run with
    /// `cfg`, ending with `Ended` when `ended`; returns it with the receiver of its controls.
    /// For view snapshots and the render benchmark.
    ///
    /// # Errors
    /// The run could not start.
    pub fn after_virtual_run(
        cfg: ratelab::RunConfig,
        ended: bool,
    ) -> Result<(Self, crossbeam_channel::Receiver<Control>), ratelab::run::RunError> {
        Self::after_virtual_session(cfg, Vec::new(), ended)
    }

    /// As [`App::after_virtual_run`], with `commands` applied at their run times (sorted by
    /// time), each reported as the engine reports it: `Changed` before the first step at or
    /// after its time.
    ///
    /// # Errors
    /// The run could not start.
    pub fn after_virtual_session(
        cfg: ratelab::RunConfig,
        commands: Vec<ratelab::run::TimedCommand>,
        ended: bool,
    ) -> Result<(Self, crossbeam_channel::Receiver<Control>), ratelab::run::RunError> {
        let (tx, rx) = crossbeam_channel::unbounded();
        let mut app = Self::new(tx, "scripted".into(), None, Speed::Times(1.0));
        let steps = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let opts = ratelab::RunOptions {
            observers: vec![Box::new(Collect(steps.clone()))],
            commands: commands.clone(),
            ..ratelab::RunOptions::new()
        };
        let report = ratelab::run(&cfg, Box::new(ratelab::policy::Scripted), opts)?;
        app.on_telemetry(Telemetry::Started {
            cfg,
            policy: "scripted balancer".into(),
            recording: None,
        });
        let mut pending = commands.iter().peekable();
        let (mut graph, mut brain) = (app.graph.clone(), "scripted".to_string());
        for s in steps.lock().unwrap_or_else(|e| e.into_inner()).iter() {
            while let Some(c) = pending.next_if(|c| c.at_ns <= s.t.0) {
                app.on_telemetry(Telemetry::Changed {
                    at: Nanos(c.at_ns),
                    text: ratelab::session::describe(&c.command),
                });
                // The engine's next status shows the new settings.
                let _ = c.command.apply_to_settings(&mut graph, &mut brain);
                app.on_telemetry(Telemetry::Status {
                    now: Nanos(c.at_ns),
                    paused: false,
                    speed: app.speed,
                    rates: graph.nodes.iter().map(|n| n.rate_hz).collect(),
                    depths: graph.topics.iter().map(|t| t.depth).collect(),
                    qos: graph.topics.iter().map(|t| t.qos).collect(),
                    alive: app.alive.clone(),
                    policy: app.brain.clone(),
                    exec: None,
                    topics: None,
                });
            }
            app.on_telemetry(Telemetry::Step(Box::new(s.clone())));
        }
        if ended {
            app.on_telemetry(Telemetry::Ended {
                metrics: Box::new(report.metrics),
                reason: report.end.reason,
            });
        }
        Ok((app, rx))
    }

    /// Show a notice (a change applied, an error) in the footer.
    fn say(&mut self, text: String) {
        self.message = Some(text);
        self.message_at = Some(std::time::Instant::now());
    }

    /// What is being typed: an exact rate, the graph panel's filter, or nothing.
    pub fn typing(&self) -> super::keymap::Typing {
        use super::keymap::Typing;
        match (&self.typing, &self.nav.typing) {
            (Some(_), _) => Typing::Rate,
            (None, Some(_)) => Typing::Filter,
            (None, None) => Typing::No,
        }
    }

    /// Do ← and → move through the run (paused under the virtual clock, in the lab's own
    /// session)?
    pub fn scrubbing(&self) -> bool {
        let virtual_paused = self.paused && self.clock == "virtual" && self.attached.is_none();
        (virtual_paused || self.reviewing()) && self.typing.is_none()
    }

    fn send(&mut self, c: Control) {
        let _ = self.tx.send(c);
    }

    fn apply(&mut self, cmd: Command) {
        self.send(Control::Apply(cmd));
    }

    /// Fold one telemetry message into what the lab shows.
    fn fold(&mut self, t: Telemetry) {
        match t {
            Telemetry::Rewound { .. } | Telemetry::Sought { .. } => {}
            Telemetry::Started {
                cfg,
                policy,
                recording,
            } => self.on_started(cfg, policy, recording),
            Telemetry::Step(s) => self.on_step(*s),
            Telemetry::NodeTick {
                node,
                now,
                lateness,
                took,
            } => {
                self.timeline.push(
                    ratelab::executor::CallbackSpan {
                        node,
                        release: now.saturating_sub(lateness),
                        start: now,
                        end: now.saturating_add(took),
                    },
                    now,
                );
                if let Some(q) = self.ticks.get_mut(node) {
                    q.push_back((now, lateness, took));
                    while q
                        .front()
                        .is_some_and(|(t, ..)| now.saturating_sub(*t) > TICK_WINDOW)
                    {
                        q.pop_front();
                    }
                }
            }
            t @ Telemetry::Status { .. } => self.on_status(t),
            Telemetry::Applied(text) => self.say(text),
            Telemetry::Callbacks(spans) => {
                for s in spans {
                    self.timeline.push(s, s.end.max(self.now));
                }
            }
            Telemetry::Changed { at, text } => {
                self.note_phase(&text);
                self.new_segment(at, text);
            }
            // Marked on its node while it lasts, as a fault given at the start is; folded
            // from the journal, so a seek back before it drops it with the branch.
            Telemetry::Faulted(fault) => self.faults.injected.push(fault),
            Telemetry::ClockSwitched { at, clock } => {
                // The same run goes on: a new segment, as a change starts one.
                self.clock = clock.to_string();
                // The real clock's tick windows start again with its ticks.
                self.ticks.iter_mut().for_each(VecDeque::clear);
                self.new_segment(
                    at,
                    format!(
                        "clock → {clock} at t={:.2} s: the same run goes on (its state carried across)",
                        at.as_secs_f64()
                    ),
                );
            }
            Telemetry::Ended { metrics, reason } => self.on_ended(&metrics, &reason),
            Telemetry::Error(e) => self.say(e),
            Telemetry::NotStarted(e) => {
                self.verdict = Verdict::NotStarted;
                self.say(e);
            }
            Telemetry::Recount(e) => {
                if self.message.as_deref().is_some_and(|m| recount_of(m, &e)) {
                    self.say(e);
                }
            }
            Telemetry::Reloaded { line } => {
                self.say(line.clone());
                self.reloading = Some(line);
            }
            Telemetry::Wire(links) => {
                self.wire.resize(self.graph.topics.len(), None);
                for (i, p50, p99) in links {
                    if let Some(w) = self.wire.get_mut(i) {
                        *w = Some((p50, p99));
                    }
                }
            }
        }
    }

    /// A change at run time `at`, said in `text`, starts a new segment of the run: the
    /// totals, and the executors' counts, start again there (as the arrows do).
    fn new_segment(&mut self, at: Nanos, text: String) {
        self.live.change(at, text.clone());
        self.exec.retain(|(t, _)| *t >= at);
        // The real clock's measured rates and tick times from the change on: a box that read
        // 20.6 Hz just after a change to 5 Hz measured mostly the rate before it.
        for q in &mut self.ticks {
            q.retain(|(t, ..)| *t >= at);
        }
        self.exec_from = Some(at);
        self.say(text);
    }

    /// A run started: everything shown is its, from its configuration.
    fn on_started(
        &mut self,
        cfg: ratelab::config::RunConfig,
        policy: String,
        recording: Option<std::path::PathBuf>,
    ) {
        if !self.rewinding {
            if let Some(said) = self.on_graph.as_ref().and_then(|hook| hook(&cfg.graph)) {
                self.say(said);
            }
        }
        self.clock = cfg.clock.to_string();
        self.seed = cfg.seed;
        self.rates = cfg.graph.nodes.iter().map(|n| n.rate_hz).collect();
        self.pending_rates.clear();
        self.depths = cfg.graph.topics.iter().map(|t| t.depth).collect();
        self.qos = cfg.graph.topics.iter().map(|t| t.qos).collect();
        self.phases = (0..cfg.graph.nodes.len())
            .map(|i| cfg.phase_offsets.get(i).map_or(0.0, |p| p.as_millis_f64()))
            .collect();
        self.explained_losses.clear();
        self.lost_before_reliable.clear();
        self.lost_at_last_step.clear();
        self.faults = Faults {
            given: cfg.faults.clone(),
            injected: Vec::new(),
        };
        self.alive = cfg
            .graph
            .nodes
            .iter()
            .map(|n| n.liveliness_lease.map(|_| true))
            .collect();
        self.ticks = vec![VecDeque::new(); cfg.graph.nodes.len()];
        self.timeline.clear();
        self.exec.clear();
        self.pending_executor = None;
        self.exec_from = None;
        self.ended_with = None;
        self.final_topics = None;
        if self.graph != cfg.graph {
            self.selected = None;
        }
        self.graph = cfg.graph;
        self.brain = policy;
        self.recording = recording.map(|p| p.display().to_string());
        self.now = Nanos::ZERO;
        self.live = Live::default();
        self.history.clear();
        self.thinned.clear();
        self.estimates.clear();
        self.applied.clear();
        self.published.clear();
        self.whole.clear();
        self.last = None;
        self.verdict = Verdict::Balanced;
        self.ended_word = None;
        self.wire.clear();
        // What was said belongs to the run before (e.g. "… (from the next run)").
        self.message = None;
        self.message_at = None;
    }

    /// An actuator step: the plant, the histories drawn, the verdict.
    fn on_step(&mut self, s: StepRecord) {
        self.now = self.now.max(s.t);
        self.live.push(s.clone());
        let now_s = s.t.as_secs_f64();
        if now_s <= GHOST_S {
            self.whole
                .push((now_s, s.pole_angle, s.action * GEAR_N, s.latency));
        }
        self.history.push_back((now_s, s.pole_angle));
        self.thinned.push(now_s, s.pole_angle, s.action * GEAR_N);
        // Drawn where the θ line shows the state it estimates, at the previous step's time;
        // folded as the summary folds it.
        self.estimates.push(&s);
        self.applied.push_back((now_s, s.action * GEAR_N));
        if let Some((at, newtons)) = s.published {
            self.published.push_back((at.as_secs_f64(), newtons));
        }
        for q in [&mut self.history, &mut self.applied, &mut self.published] {
            while q.front().is_some_and(|(t, _)| now_s - t > HISTORY_S) {
                q.pop_front();
            }
        }
        if s.fell {
            self.verdict = Verdict::Fell(s.t.as_secs_f64());
        }
        self.explain_reliable_losses(&s);
        self.last = Some(s);
    }

    /// The engine's status: counters, executors' figures, rates (those asked for and not
    /// yet taken stand), depths, QoS, liveliness and the brain.
    fn on_status(&mut self, t: Telemetry) {
        let Telemetry::Status {
            now,
            paused,
            speed,
            rates,
            depths,
            qos,
            alive,
            policy,
            exec,
            topics,
        } = t
        else {
            return;
        };
        if let Some(topics) = topics {
            self.live.counters(super::live::Counts {
                t: now,
                topics: *topics,
            });
        }
        // Counted at `now`: rates are taken between counts, over the window.
        match exec {
            Some(e) => {
                self.exec.push_back((now, e));
                let from = now.saturating_sub(super::live::WINDOW);
                while self.exec.get(1).is_some_and(|(t, _)| *t <= from) {
                    self.exec.pop_front();
                }
            }
            None => self.exec.clear(),
        }
        self.now = self.now.max(now);
        self.paused = paused;
        self.speed = speed;
        self.rates = merge_pending(&mut self.pending_rates, rates, now);
        self.depths = depths;
        self.qos = qos;
        self.alive = alive;
        self.brain = policy;
    }

    /// The run ended: the settings it ended with (the next run's start from them), its
    /// verdict, and what to do next.
    fn on_ended(&mut self, metrics: &ratelab::metrics::Metrics, reason: &EndReason) {
        if self.ended_with.is_none() {
            let rates = (0..self.graph.nodes.len())
                .map(|i| self.rate_of(NodeId(i)))
                .collect();
            let topics = 0..self.graph.topics.len();
            let depths = topics.clone().map(|i| self.depth_of(TopicId(i))).collect();
            let qos = topics.map(|i| self.qos_of(TopicId(i))).collect();
            self.ended_with = Some((rates, depths, qos));
        }
        if self.attached.is_some() {
            self.final_topics = Some(metrics.topics.clone());
        }
        self.estimates.ended(metrics.estimate.as_ref());
        self.verdict = match reason {
            EndReason::NodeFailed { node, message } => {
                Verdict::Failed(format!("{node}: {message}"))
            }
            _ => match (metrics.fell_at_s, metrics.headline()) {
                (Some(t), _) => Verdict::Fell(t),
                (None, h) if h == ratelab::metrics::BALANCED_WHOLE_RUN => Verdict::Done,
                // A watchdog stop, a plant that never stepped, an early stop.
                (None, h) => Verdict::Stopped(h),
            },
        };
        let reason = reason.words(metrics.stopped_by_watchdog.is_some());
        let ended = match (metrics.sched_warning(), &self.attached) {
            (Some(w), _) => format!("{reason} — {w}"),
            (None, Some(_)) => format!("{reason} — the launch is over · q quit"),
            (None, None) => {
                format!("{reason} — keys set the next run · r/R reset · c clock · q quit")
            }
        };
        // A failed node's script read as the log pane reads it: relative to the graph file.
        let ended = match &self.code_folder {
            Some(folder) => log::relative_to(&ended, folder),
            None => ended,
        };
        // A run of code just saved keeps its reload line in the footer (what changed, read
        // whole), and says how it ended in the status bar.
        match self.run_reload.clone() {
            Some(line) => {
                self.ended_word = Some(ended);
                self.say(line);
            }
            None => self.say(ended),
        }
    }

    /// The node `-`/`+`/`=` act on: the selected node, else the chain's policy, else (a
    /// graph without the chapter's chain) the first node that is not the actuator.
    fn rate_target(&self) -> NodeId {
        match (self.selected, self.graph.chain) {
            (Some(Selected::Node(n)), _) => n,
            (_, Some(c)) => c.policy,
            (_, None) => NodeId(
                (0..self.graph.nodes.len())
                    .find(|&i| NodeId(i) != self.graph.actuator)
                    .unwrap_or(0),
            ),
        }
    }

    /// The chain's node `pick` names (callers checked the graph has the chain).
    fn rate_target_of_chain(&self, pick: impl Fn(ratelab::graph::Chain) -> NodeId) -> NodeId {
        self.graph.chain.map_or(self.rate_target(), pick)
    }

    fn rate_of(&self, n: NodeId) -> f64 {
        self.rates
            .get(n.0)
            .copied()
            .unwrap_or(self.graph.node(n).rate_hz)
    }

    /// Topic `t`'s history depth as set (after a fall, the next run's).
    fn depth_of(&self, t: TopicId) -> usize {
        self.depths
            .get(t.0)
            .copied()
            .unwrap_or(self.graph.topic(t).depth)
    }

    /// Topic `t`'s QoS as set (after a fall, the next run's).
    fn qos_of(&self, t: TopicId) -> TopicQos {
        self.qos
            .get(t.0)
            .copied()
            .unwrap_or(self.graph.topic(t).qos)
    }

    /// Handle one key message.
    pub fn on_msg(&mut self, m: Msg) {
        let confirming = std::mem::take(&mut self.confirm_quit);
        // Typing the graph panel's filter (in an attached lab too: it changes only the view).
        if self.nav.typing.is_some() {
            use super::navigate::NavKey;
            let key = match m {
                Msg::Input(c) => NavKey::Input(c),
                Msg::Backspace => NavKey::Backspace,
                Msg::Submit => NavKey::Submit,
                Msg::Cancel => NavKey::Cancel,
                Msg::Quit | Msg::Interrupt => return self.on_msg_typed(m, confirming),
                _ => return,
            };
            self.nav.on_key(key);
            return;
        }
        self.on_msg_typed(m, confirming);
    }

    /// Handle one key message, nothing being typed but a rate (`confirming`: the Esc before
    /// asked whether to quit).
    fn on_msg_typed(&mut self, m: Msg, confirming: bool) {
        // Attached, a key that would change the graph changes nothing here either.
        if self.attached.is_some() && !m.only_views() {
            self.say(READ_ONLY.to_string());
            return;
        }
        // Reviewing, the screen is the run as it was: a change would not show.
        let moves = m.is_seek()
            || matches!(
                m,
                Msg::TogglePause | Msg::Reset | Msg::NextSeed | Msg::SwitchClock
            );
        if self.reviewing() && !m.only_views() && !moves {
            self.say("reviewing the run as recorded: space leaves, then change it".into());
            return;
        }
        match m {
            Msg::RateDown => {
                let n = self.rate_target();
                self.set_rate(n, rate_down(self.rate_of(n)));
            }
            Msg::RateUp => {
                let n = self.rate_target();
                self.set_rate(n, rate_up(self.rate_of(n)));
            }
            Msg::Break | Msg::SensorDown | Msg::SensorUp if self.graph.chain.is_none() => {
                self.say(NO_CHAIN.to_string());
            }
            Msg::Break => {
                let n = self.rate_target_of_chain(|c| c.policy);
                self.set_rate(n, BREAK_CONTROL_HZ);
            }
            Msg::Stall => {
                let n = self.rate_target();
                // From the run's next instant, not the time drawn, which trails it at ×8 and
                // at max speed (the engine books the fault as it takes effect).
                self.send(Control::Stall {
                    node: self.graph.node(n).name.clone(),
                    duration: ratelab::Nanos::from_secs_f64(super::keymap::STALL_S)
                        .unwrap_or_default(),
                });
            }
            Msg::SensorDown => {
                let n = self.rate_target_of_chain(|c| c.sensor);
                self.set_rate(n, rate_down(self.rate_of(n)));
            }
            Msg::SensorUp => {
                let n = self.rate_target_of_chain(|c| c.sensor);
                self.set_rate(n, rate_up(self.rate_of(n)));
            }
            Msg::DepthDown => self.change_depth(depth_down),
            Msg::DepthUp => self.change_depth(depth_up),
            Msg::ToggleDelivery
            | Msg::CycleDeadline
            | Msg::CycleLoss
            | Msg::CycleLifespan
            | Msg::ToggleReliability
            | Msg::CycleOnDeadlineMissed => self.change_qos(m),
            Msg::SelectNext => self.selected = self.cycle(1),
            Msg::SelectPrev => self.selected = self.cycle(-1),
            Msg::Zoom
            | Msg::ScrollUp
            | Msg::ScrollDown
            | Msg::ScrollTop
            | Msg::Filter
            | Msg::ToggleTrouble => self.navigate(m),
            Msg::TypeRate => self.typing = Some(String::new()),
            Msg::CyclePhase => self.cycle_phase(),
            Msg::Input(c) => {
                if let Some(t) = &mut self.typing {
                    // `10000.125` and a little more; past it, nothing a rate needs.
                    if t.chars().count() < 16 {
                        t.push(c);
                    }
                }
            }
            Msg::Backspace => {
                if let Some(t) = &mut self.typing {
                    t.pop();
                }
            }
            Msg::Cancel => self.typing = None,
            Msg::Submit => self.submit_rate(),
            // An ended real-clock run is reviewed: the engine cannot run it again.
            Msg::TogglePause if self.reviewing() || self.can_review() => self.toggle_review(),
            Msg::TogglePause => self.send(Control::TogglePause),
            Msg::Step => self.send(Control::Step),
            Msg::SeekBack { second } | Msg::SeekForward { second } => {
                self.seek(matches!(m, Msg::SeekBack { .. }), second)
            }
            Msg::Reset => self.send(Control::Reset { next_seed: false }),
            Msg::NextSeed => self.send(Control::Reset { next_seed: true }),
            Msg::SwitchClock => self.send(Control::SwitchClock),
            Msg::Slower | Msg::Faster => self.change_speed(m == Msg::Slower),
            Msg::ChartsNarrower | Msg::ChartsWider => {
                self.chart_window = if m == Msg::ChartsNarrower {
                    self.chart_window.narrower()
                } else {
                    self.chart_window.wider()
                };
                self.say(format!("charts: {}", self.chart_window.label()));
            }
            Msg::SwapBrain => self.swap_brain(),
            Msg::ToggleHelp => self.help = !self.help,
            Msg::ToggleTimeline => {
                self.show_timeline = !self.show_timeline;
                self.show_log = false;
                self.log_open = None;
            }
            Msg::ToggleLog => {
                self.show_log = !self.show_log;
                self.log_back = 0;
                self.log_open = None;
            }
            Msg::ToggleRos2 if self.ros2_domain.is_none() => {
                self.say(
                    "not offered to ROS 2: start the lab with --ros2 to see the graph as ROS 2 sees it"
                        .to_string(),
                );
            }
            Msg::ToggleRos2 => self.show_ros2 = !self.show_ros2,
            Msg::LogOlder | Msg::LogNewer if self.log_open.is_some() => {
                self.scroll_entry(m == Msg::LogOlder)
            }
            Msg::LogEntry => self.toggle_entry(),
            Msg::LogOlder if self.show_log => {
                self.log_back = (self.log_back + LOG_PAGE).min(self.log.len().saturating_sub(1));
            }
            Msg::LogNewer if self.show_log => {
                self.log_back = self.log_back.saturating_sub(LOG_PAGE)
            }
            Msg::LogOlder | Msg::LogNewer => {}
            Msg::CycleExecutor => self.cycle_executor(),
            Msg::Back => self.back(confirming),
            Msg::Quit => {
                self.send(Control::Quit);
                self.quit = true;
            }
            Msg::Interrupt => self.interrupt(),
        }
    }

    /// Enter on a typed rate: set it on the node `-`/`+` act on, or say why not.
    fn submit_rate(&mut self) {
        let text = self.typing.take().unwrap_or_default();
        match text
            .parse::<f64>()
            .map_err(|_| ())
            .and_then(|hz| check_rate("rate", hz).map_err(|_| ()))
        {
            Ok(hz) => self.set_rate(self.rate_target(), hz),
            Err(()) => self.say(format!("not a rate in (0, 10000] Hz: '{text}'")),
        }
    }

    /// The next slower or faster speed of [`SPEEDS`].
    fn change_speed(&mut self, slower: bool) {
        let i = SPEEDS.iter().position(|s| *s == self.speed).unwrap_or(2);
        let j = if slower {
            i.saturating_sub(1)
        } else {
            (i + 1).min(SPEEDS.len() - 1)
        };
        // At either end of the ladder under the virtual clock, said rather than sent again
        // (the key did nothing you could see). The real clock's refusal is the engine's.
        if j == i && self.clock == "virtual" {
            let (end, other) = if slower {
                ("slowest", "> speeds up")
            } else {
                ("fastest", "< slows down")
            };
            return self.say(format!("already the {end} speed ({}): {other}", SPEEDS[i]));
        }
        self.speed = SPEEDS[j];
        self.send(Control::SetSpeed(self.speed));
    }

    /// Swap the scripted brain and the `--policy` one.
    fn swap_brain(&mut self) {
        match self.alt_policy.clone() {
            Some(alt) => {
                let spec = if self.policy_spec == "scripted" {
                    alt
                } else {
                    "scripted".to_string()
                };
                self.policy_spec = spec.clone();
                self.apply(Command::SetPolicy { spec });
            }
            None => {
                self.say("no --policy file given: nothing to swap the scripted brain with".into())
            }
        }
    }

    /// The next executor: one per node → one thread for all → two threads → one per node.
    fn cycle_executor(&mut self) {
        // One per node → one thread for all → two threads → one per node.
        let current = self.pending_executor.unwrap_or_else(|| {
            match self.graph.executors.first().map(|e| e.kind) {
                None => "per_node",
                Some(ExecutorKind::SingleThreaded) => "single_threaded",
                Some(_) => "multi_threaded:2",
            }
        });
        let next = match current {
            "per_node" => "single_threaded",
            "single_threaded" => "multi_threaded:2",
            _ => "per_node",
        };
        if self.clock == "real" || self.ended_with.is_some() {
            // From the next run (the real clock's threads are made at its start; a
            // run that ended keeps its frozen timeline).
            self.pending_executor = Some(next);
        } else if let Ok(over) = ExecutorOverride::parse(next) {
            self.graph.set_executor(over);
        }
        // The timeline shows what the executors do.
        self.show_timeline = true;
        self.apply(Command::SetExecutor {
            executor: next.to_string(),
        });
    }

    /// Esc: close the help, else the log entry shown whole, else clear the selection, else
    /// ask before quitting (a second Esc, `confirming`, quits).
    fn back(&mut self, confirming: bool) {
        if self.help {
            self.help = false;
        } else if self.log_open.is_some() {
            self.log_open = None;
        } else if self.selected.is_some() {
            self.selected = None;
        } else if self.nav.clear_filter() {
            self.say("graph: filter cleared, everything shown".into());
        } else if confirming {
            self.on_msg(Msg::Quit);
        } else {
            self.confirm_quit = true;
            self.say("quit? Esc again or q quits; any other key stays".into());
        }
    }

    /// The selection `step` places on from the current one, around the ring
    /// nothing → node 0 … node n−1 → topic 0 … topic m−1 → nothing, past what the graph
    /// panel's filter hides.
    fn cycle(&self, step: isize) -> Option<Selected> {
        let nodes = self.graph.nodes.len();
        let ring = nodes + self.graph.topics.len() + 1;
        let (node_views, topic_views) = self.graph_views(self.hung_callback().as_ref());
        let shown = |p: usize| match p {
            0 => true,
            p if p <= nodes => node_views[p - 1].shown,
            p => topic_views[p - 1 - nodes].shown,
        };
        let mut pos = match self.selected {
            None => 0,
            Some(Selected::Node(n)) => 1 + n.0,
            Some(Selected::Topic(t)) => 1 + nodes + t.0,
        };
        for _ in 0..ring {
            pos = (pos as isize + step).rem_euclid(ring as isize) as usize;
            if shown(pos) {
                break;
            }
        }
        match pos {
            0 => None,
            p if p <= nodes => Some(Selected::Node(NodeId(p - 1))),
            p => Some(Selected::Topic(TopicId(p - 1 - nodes))),
        }
    }

    /// A key of the graph panel's navigation ([`super::navigate`]).
    fn navigate(&mut self, m: Msg) {
        use super::navigate::NavKey;
        let key = match m {
            Msg::Zoom => NavKey::Zoom,
            Msg::ScrollUp => NavKey::Up(1),
            Msg::ScrollDown => NavKey::Down(1),
            Msg::ScrollTop => NavKey::Top,
            Msg::Filter => NavKey::StartFilter,
            _ => NavKey::ToggleTrouble,
        };
        if let Some(said) = self.nav.on_key(key) {
            self.say(said);
        }
    }

    /// Set node `n`'s rate. The chapter's nodes keep the chapter's commands, so a session
    /// log of the default graph reads as before.
    fn set_rate(&mut self, n: NodeId, hz: f64) {
        if let Some(r) = self.rates.get_mut(n.0) {
            *r = hz;
        }
        if self.pending_rates.len() <= n.0 {
            self.pending_rates.resize(n.0 + 1, None);
        }
        self.pending_rates[n.0] = Some((hz, self.now));
        let chain = self.graph.chain;
        let cmd = if chain.is_some_and(|c| n == c.policy) {
            Command::SetControlHz { hz }
        } else if chain.is_some_and(|c| n == c.sensor) {
            Command::SetSensorHz { hz }
        } else {
            Command::SetNodeHz {
                node: self.graph.node(n).name.clone(),
                hz,
            }
        };
        self.apply(cmd);
    }
}

/// The most lines of the run's text log the lab keeps (the pane shows the newest).
pub const LOG_LINES: usize = 2000;

/// The most telemetry messages a run's journal keeps for seeking back (about an hour of a
/// run at ×1): past it, seeking back still puts the run there, but the lab's figures go on
/// from there instead of showing the run as it was.
pub const MAX_JOURNAL: usize = 400_000;

/// The most bytes a run's journal keeps ([`Telemetry::approx_bytes`]): a large graph's steps
/// carry every topic's counters (a 1,000-topic step is about 140 KB), so its journal stops
/// after minutes, not an hour; seeking back past that goes on as [`MAX_JOURNAL`] says.
pub const MAX_JOURNAL_BYTES: usize = 512 << 20;

/// How many lines PgUp / PgDn scroll the log pane.
pub const LOG_PAGE: usize = 3;

/// How long a learner's callback runs without returning before the lab shows it hung.
pub use ratelab::python::HUNG_AFTER;

/// How long (run time) a rate asked for outranks the engine's status: its command is taken
/// at the next instant, so a status without it after this long means it was refused.
const PENDING_RATE: ratelab::Nanos = ratelab::Nanos(1_000_000_000);

/// The rates to show, from a status's `rates` at run time `now`: a rate still `pending`
/// (asked for, not yet in a status, asked less than [`PENDING_RATE`] ago) stands over the
/// status's; one the status shows, or too old, is no longer pending.
fn merge_pending(
    pending: &mut [Option<(f64, ratelab::Nanos)>],
    mut rates: Vec<f64>,
    now: ratelab::Nanos,
) -> Vec<f64> {
    for (i, p) in pending.iter_mut().enumerate() {
        let Some((hz, asked)) = *p else { continue };
        let seen = rates.get(i) == Some(&hz);
        if seen || now.saturating_sub(asked) > PENDING_RATE {
            *p = None;
        } else if let Some(r) = rates.get_mut(i) {
            *r = hz;
        }
    }
    rates
}

/// `new` is `shown` with other numbers (the same words around its counts): a
/// [`Telemetry::Recount`] of the line on screen.
fn recount_of(shown: &str, new: &str) -> bool {
    let words = |s: &str| -> String { s.chars().filter(|c| !c.is_ascii_digit()).collect() };
    words(shown) == words(new)
}

#[cfg(test)]
mod pending_tests {
    use super::{merge_pending, recount_of};

    /// A recount replaces the line it counts, not another message.
    #[test]
    fn a_recount_is_the_same_words_with_another_count() {
        let first =
            "reload of a.py: its callback has not returned after 2 s of the trial run (t=0.50 s)";
        let again =
            "reload of a.py: its callback has not returned after 13 s of the trial run (t=0.50 s)";
        assert!(recount_of(first, again));
        assert!(!recount_of("Ctrl-C: the run on screen is not hung", again));
    }
    use ratelab::Nanos;

    #[test]
    fn a_rate_asked_for_outranks_a_status_sent_before_it_was_taken() {
        let ms = |n: u64| Nanos(n * 1_000_000);
        let mut pending = vec![None, Some((40.0, ms(100)))];
        // A status from before the command: the asked rate stands.
        assert_eq!(
            merge_pending(&mut pending, vec![50.0, 50.0], ms(110)),
            [50.0, 40.0]
        );
        assert!(pending[1].is_some());
        // The status that shows it: no longer pending, the status stands from then on.
        assert_eq!(
            merge_pending(&mut pending, vec![50.0, 40.0], ms(120)),
            [50.0, 40.0]
        );
        assert!(pending[1].is_none());
        assert_eq!(
            merge_pending(&mut pending, vec![50.0, 30.0], ms(130)),
            [50.0, 30.0]
        );
        // Refused (never shown): after a second of run time the engine's rate stands.
        let mut pending = vec![Some((40.0, ms(0)))];
        assert_eq!(merge_pending(&mut pending, vec![50.0], ms(500)), [40.0]);
        assert_eq!(merge_pending(&mut pending, vec![50.0], ms(1_200)), [50.0]);
        assert!(pending[0].is_none());
    }

    #[test]
    fn a_latency_reads_down_to_its_tenth_as_its_bar_counts_it() {
        use super::tenth_ms_down;
        // In the `<200` bar, so not `200.0`, however close (to the nanosecond).
        for ns in [199_960_000, 199_999_600, 199_999_999] {
            assert_eq!(format!("{:.1}", tenth_ms_down(Nanos(ns))), "199.9");
        }
        for (ns, text) in [
            (200_000_000, "200.0"),
            (300_000, "0.3"),
            (40_200_000, "40.2"),
            (0, "0.0"),
            (19_990_000, "19.9"),
        ] {
            assert_eq!(format!("{:.1}", tenth_ms_down(Nanos(ns))), text);
        }
    }
}
