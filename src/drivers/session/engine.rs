//! The engine: owns the graph on its own thread, runs one run after another as the front
//! end asks (reset, next seed, switch clock), applies and logs commands, streams telemetry.

use super::log::{LoggedRun, SessionLog};
use crate::run::{build_graph, summarize, Command, TimedCommand};
use crossbeam_channel::{Receiver, Sender};
use ratelab_core::metrics::{Metrics, NodeTiming};
use ratelab_core::runlog::StepRecord;
use ratelab_core::time::Nanos;
use ratelab_recording::{RecordOptions, Recording};
use ratelab_runtime::checkpoint::load_policy;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::graph::{GraphHandles, StepObserver};
use ratelab_runtime::policy::BrainSlot;
use ratelab_runtime::runcore::{CoreOptions, RunCore, HISTORY_EVERY};
use ratelab_runtime::scheduler::RunEnd;
use ratelab_runtime::telemetry::{describe, Control, Speed, Telemetry};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Where the lab's graph comes from, read again when a file is saved ([`Control::Reload`]):
/// the graph file with the command line's overrides (`--rate`, `--depth`, `--qos`, …)
/// applied, as at the start.
#[derive(Clone)]
pub struct GraphSource(
    pub Arc<dyn Fn() -> Result<ratelab_runtime::graph::GraphSpec, String> + Send + Sync>,
);

impl std::fmt::Debug for GraphSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GraphSource")
    }
}

/// How the lab's engine starts.
#[derive(Clone, Debug)]
pub struct SessionSettings {
    /// The first run's settings (`duration` may be [`super::UNBOUNDED`]).
    pub cfg: RunConfig,
    /// The first run's brain spec.
    pub policy: String,
    /// The checkpoint the `p` key swaps with `scripted`, if one was given.
    pub alt_policy: Option<String>,
    /// Record each run (the first to this path; later ones get `-2`, `-3`, … suffixes).
    pub record: Option<PathBuf>,
    /// Stream recordings to a viewer as well.
    pub spawn: bool,
    /// Record only this span of each run's time (`--record-window`).
    pub record_window: Option<ratelab_recording::RecordWindow>,
    /// Where to save the session log after every run and command.
    pub session_file: Option<PathBuf>,
    /// Start paused.
    pub start_paused: bool,
    /// Initial virtual speed.
    pub speed: Speed,
    /// Replace existing recordings (the lab's `--force`); without it a run whose recording
    /// file exists is refused, never overwritten. The session log is checked once, by the
    /// caller, before the session starts, and then rewritten by the session as it goes.
    pub force: bool,
    /// Offer each run's graph to ROS 2 through this session ([`ratelab_ros2`]), opened by the
    /// caller before the session starts (one session, one router, for all runs).
    pub ros2: Option<(
        ratelab_ros2::session::Ros2Session,
        ratelab_ros2::Ros2Options,
    )>,
    /// Where the front end's controls go (its own sender of them): a node's `rate_hz` set
    /// from ROS 2 arrives as its rate key's command would. `None`: read-only over ROS 2.
    pub control: Option<Sender<Control>>,
    /// Where the graph is read again when a file is saved ([`Control::Reload`]); `None`:
    /// the graph stays as it is (the compiled-in chapter's), and only brains reload.
    pub graph_source: Option<GraphSource>,
}

/// How long a fresh run that judges a live rate change runs at most
/// ([`Engine::judge_fresh_run`]): 30 s of run time (about 60 ms of CPU).
pub const JUDGE_FOR: Nanos = Nanos(30 * Nanos::SECOND.0);

/// Streams step records to the front end.
/// Streams step records to the front end, unless muted (while a seek back runs the run again
/// to the instant asked for: the front end has those steps already).
#[derive(Clone)]
pub(super) struct TelemetryObserver(Sender<Telemetry>, Arc<AtomicBool>);

impl TelemetryObserver {
    /// A boxed copy, for a graph's observers.
    pub(super) fn observer(&self) -> Box<dyn StepObserver> {
        Box::new(self.clone())
    }
}

impl StepObserver for TelemetryObserver {
    fn on_step(&mut self, rec: &StepRecord) {
        if !self.1.load(Ordering::Relaxed) {
            let _ = self.0.send(Telemetry::Step(Box::new(rec.clone())));
        }
    }
}

/// The engine: run sessions until [`Control::Quit`]; returns the session log.
pub struct Engine {
    pub(super) settings: SessionSettings,
    pub(super) rx: Receiver<Control>,
    pub(super) tx: Sender<Telemetry>,
    log: SessionLog,
    pub(super) speed: Speed,
    run_index: usize,
    /// Changes made while a run was frozen (after a fall or its end): they set the next run.
    next_run: Vec<Command>,
    /// The brain spec the current run started with (for [`Engine::judge_fresh_run`]).
    pub(super) run_policy: String,
    /// Mutes the step telemetry while a seek back runs the run again.
    pub(super) muted: Arc<AtomicBool>,
    /// The graph as its files gave it when they were last read (at the start, or a save's
    /// reload): what a save under the real clock is compared with, not the run's graph,
    /// whose rates and depths the keys may have changed since.
    pub(super) file_graph: ratelab_runtime::graph::GraphSpec,
    /// A save's code loading, or being judged, on a thread of its own (see
    /// [`super::reload`]).
    pub(super) reloading: Option<super::trial::Pending>,
    /// Reloads superseded or dropped, watched until their threads end.
    pub(super) cancelled: Vec<super::trial::Cancelled>,
    /// Node rates set from ROS 2 (`ros2 param set NODE rate_hz HZ`), (node, Hz), not yet
    /// applied: the command that applies one is recorded as a ROS 2 parameter set.
    ros2_sets: Arc<std::sync::Mutex<Vec<(String, f64)>>>,
    /// The run's actuator ticks over its first [`JUDGE_FOR`], which a save's reload line
    /// compares the new code's with ([`super::compare`]).
    pub(super) opening: super::compare::Opening,
}

/// How a run of the lab ended, for the next: what the user asked, and the graph (rates,
/// depths), brain and clock it ended with.
struct RunOutcome {
    next: Next,
    graph: ratelab_runtime::graph::GraphSpec,
    policy: String,
    clock: ClockKind,
}

/// A part of a run under one clock, as it ended: what the user asked next, how the run
/// ended (interrupted then, unless it had ended), the real clock's tick timing and the
/// executors' figures.
pub(super) type Segment = (
    Next,
    RunEnd,
    Option<Vec<NodeTiming>>,
    Option<ratelab_core::executor::ExecFigures>,
);

/// What ended a run from the engine's side.
pub(super) enum Next {
    Reset {
        next_seed: bool,
    },
    SwitchClock,
    /// A saved file was taken up: the next run is this (the new code's), from t = 0.
    Reload(Box<RunConfig>),
    Quit,
}

impl Engine {
    /// A new engine; call [`Engine::run`] on its own thread.
    pub fn new(settings: SessionSettings, rx: Receiver<Control>, tx: Sender<Telemetry>) -> Self {
        let speed = settings.speed;
        let file_graph = settings.cfg.graph.clone();
        Self {
            file_graph,
            settings,
            rx,
            tx,
            log: SessionLog::new(),
            speed,
            run_index: 0,
            next_run: Vec::new(),
            run_policy: String::new(),
            muted: Arc::new(AtomicBool::new(false)),
            reloading: None,
            cancelled: Vec::new(),
            ros2_sets: Arc::default(),
            opening: super::compare::Opening::upto(JUDGE_FOR),
        }
    }

    /// Spawn the engine on a thread named `engine`.
    pub fn spawn(self) -> std::thread::JoinHandle<SessionLog> {
        std::thread::Builder::new()
            .name("engine".into())
            .spawn(move || self.run())
            .expect("spawning the engine")
    }

    fn save_log(&self) {
        if let Some(p) = &self.settings.session_file {
            if let Err(e) = self.log.save(p) {
                let _ = self.tx.send(Telemetry::Error(format!(
                    "cannot save session {}: {e}",
                    p.display()
                )));
            }
        }
    }

    /// Run until quit. Returns the session log.
    pub fn run(mut self) -> SessionLog {
        let mut cfg = self.settings.cfg.clone();
        let mut policy = self.settings.policy.clone();
        loop {
            let next = match self.one_run(&cfg, &policy) {
                Ok(RunOutcome {
                    next: Next::Reload(new),
                    policy: last_policy,
                    ..
                }) => {
                    // The new code's graph, as the files now give it; the brain as it was.
                    self.file_graph = new.graph.clone();
                    cfg = *new;
                    policy = last_policy;
                    self.next_run.clear();
                    continue;
                }
                Ok(RunOutcome {
                    next,
                    graph,
                    policy: last_policy,
                    clock,
                }) => {
                    // The next run keeps the settings as the user left them (the clock it
                    // went on under included), and takes the changes made while this one
                    // was frozen (checked when they were made).
                    cfg.graph = graph;
                    cfg.clock = clock;
                    policy = last_policy;
                    for cmd in self.next_run.drain(..) {
                        let _ = cmd.apply_to_settings(&mut cfg.graph, &mut policy);
                    }
                    next
                }
                Err(e) => {
                    let _ = self.tx.send(Telemetry::NotStarted(e));
                    // Wait for the user's decision (a change sent meanwhile, from ROS 2's
                    // `param set`, is not one: it has no run to go to; nor are keys that
                    // act on a run). A save starts the run again with what the files hold.
                    loop {
                        match self.rx.recv() {
                            Ok(Control::Reset { next_seed }) => break Next::Reset { next_seed },
                            Ok(Control::SwitchClock) => break Next::SwitchClock,
                            Ok(Control::Reload { .. }) => match self.reloaded_config(&cfg) {
                                Ok(new) => break Next::Reload(Box::new(new)),
                                Err(e) => {
                                    let _ = self.tx.send(Telemetry::Error(e));
                                }
                            },
                            Ok(Control::Quit) | Err(_) => break Next::Quit,
                            Ok(_) => continue,
                        }
                    }
                }
            };
            match next {
                Next::Quit => break,
                Next::Reset { next_seed } => {
                    if next_seed {
                        cfg.seed += 1;
                    }
                }
                Next::SwitchClock => cfg.clock = cfg.clock.other(),
                Next::Reload(new) => {
                    self.file_graph = new.graph.clone();
                    cfg = *new;
                }
            }
        }
        // A save's trial still under way is stopped (interrupted, if stuck).
        self.drop_reload(false);
        self.save_log();
        self.log
    }

    fn recording_path(&self) -> Option<PathBuf> {
        let base = self.settings.record.as_ref()?;
        if self.run_index == 1 {
            return Some(base.clone());
        }
        let stem = base
            .file_stem()
            .map_or("run".into(), |s| s.to_string_lossy().into_owned());
        Some(base.with_file_name(format!("{stem}-{}.rrd", self.run_index)))
    }

    /// One run, under one clock or, switched in place, both; returns what the user asked
    /// next, and the graph (rates, depths), brain and clock it ended with.
    fn one_run(&mut self, cfg: &RunConfig, policy: &str) -> Result<RunOutcome, String> {
        self.run_index += 1;
        self.run_policy = policy.to_string();
        // What this run's code is read from here: the code of the run on screen, which a
        // save not taken up leaves pinned (`reload::pin_code_before`).
        ratelab_runtime::graph::interpreter::forget_scripts_read();
        let brain = load_policy(policy).map_err(|e| e.to_string())?;
        let (recording, notice) = self.create_recording(cfg, &brain.label())?;
        // What the nodes' code writes goes in the recording too (`log/<node>`), as a
        // headless run's does — a script's loading included — until the run ends.
        let mut recorder = recording
            .clone()
            .map(|r| ratelab_core::textlog::add_recorder(Box::new(move |line| r.log_line(&line))));
        // This run's first ticks, for a save's reload line (a new run, a new opening).
        self.opening = super::compare::Opening::upto(JUDGE_FOR);
        let mut observers = vec![
            self.telemetry_observer().observer(),
            self.opening.observer(),
        ];
        if let Some(r) = &recording {
            observers.push(r.observer());
        }
        let slot = BrainSlot::new(brain);
        let graph = build_graph(cfg, slot, false, observers).map_err(|e| e.to_string())?;
        let _ = self.tx.send(Telemetry::Started {
            cfg: cfg.clone(),
            policy: graph.handles.brain_label(),
            recording: recording.as_ref().map(|r| r.path().to_path_buf()),
        });
        // Said after Started, which clears what the lab said about the run before.
        if let Some(n) = notice {
            let _ = self.tx.send(Telemetry::Error(n));
        }
        let bridge = match &self.settings.ros2 {
            Some((link, opts)) => {
                let h = &graph.handles;
                if let Some(x) = h.external.first() {
                    let _ = self.tx.send(Telemetry::Applied(format!(
                        "waiting for external node '{}' on ROS 2 domain {}…",
                        x.name, opts.domain
                    )));
                }
                let set_rate = self.ros2_set_rate();
                let offer = ratelab_ros2::bridge::Offer {
                    set_rate,
                    ..ratelab_ros2::bridge::Offer::whole(h)
                };
                let stop = ratelab_runtime::scheduler::StopFlag::new();
                match ratelab_ros2::Bridge::start(link, &offer, opts, cfg.clock, &stop) {
                    Ok(b) => {
                        let _ = self.tx.send(Telemetry::Applied(b.status()));
                        Some(b)
                    }
                    // Without its external nodes the graph cannot run.
                    Err(e) if !h.external.is_empty() => return Err(format!("ROS 2: {e}")),
                    Err(e) => {
                        let _ = self.tx.send(Telemetry::Error(format!("ROS 2: {e}")));
                        None
                    }
                }
            }
            None => None,
        };
        self.log.runs.push(LoggedRun::starting(cfg, policy));
        self.save_log();
        let policy_spec = policy.to_string();
        let telemetry = self.telemetry_observer();
        let opening = self.opening.clone();
        let mut core = RunCore::with_graph(
            cfg,
            graph,
            CoreOptions {
                on_span: recording.as_ref().and_then(Recording::span_hook),
                // Time travel (Control::Seek): a capture every second of run time; a graph
                // whose captures replay makes its brain and telemetry again.
                history_every: Some(HISTORY_EVERY),
                remake_brain: Some(Box::new(move || {
                    load_policy(&policy_spec).map_err(|e| e.to_string())
                })),
                remake_observers: Some(Box::new(move || {
                    vec![telemetry.observer(), opening.observer()]
                })),
                ..CoreOptions::default()
            },
        );
        // The settings as they stand: under the clock the run goes on under.
        let mut under = cfg.clone();
        let mut resumed = false;
        let (next, end, timing, exec) = loop {
            let part = match under.clock {
                ClockKind::Virtual => {
                    self.virtual_run(&mut core, &under, &recording, bridge.as_ref(), resumed)
                }
                ClockKind::Real => self.real_run(&mut core, &under, &recording),
            };
            // `c` on a run still going switches its clock in place; on a run that ended, or
            // one offered to ROS 2 (its bridge serves the clock it started with), the next
            // run starts under the other clock.
            if matches!(part.0, Next::SwitchClock) && core.end().is_none() && bridge.is_none() {
                under.clock = under.clock.other();
                resumed = true;
                self.clock_switched(under.clock, core.now());
                if let Some(r) = &recording {
                    r.clock_switched(core.now(), under.clock);
                }
                continue;
            }
            break part;
        };
        // A save still loading was made in this run: the next starts with the code before
        // (a save that loaded has been taken up: `next` is its run).
        self.drop_reload(!matches!(next, Next::Quit));
        let handles = core.handles().clone();
        let ticks = core.scheduler().ticks().to_vec();
        if let Some(r) = bridge.map(ratelab_ros2::Bridge::finish) {
            if let Some(e) = &r.error {
                let _ = self
                    .tx
                    .send(Telemetry::Error(format!("ROS 2: a put failed: {e}")));
            }
            if let Some(w) = r.external_warnings().into_iter().next() {
                let _ = self.tx.send(Telemetry::Error(w));
            }
        }
        // The summary says the clock the run ended under (its log, where it switched).
        let metrics = live_metrics(&under, &handles, &end, &ticks, timing, exec);
        drop(recorder.take());
        if let Some(r) = &recording {
            finish_recording(r, &next, &metrics, &end);
        }
        let current = self.log.runs.last_mut().expect("pushed above");
        current.end_ns = end.at.0;
        current.metrics = Some(metrics);
        let last_policy = self.current_policy_spec(policy);
        self.save_log();
        Ok(RunOutcome {
            next,
            graph: handles.current_spec(),
            policy: last_policy,
            clock: under.clock,
        })
    }

    /// The running graph went on under `clock` at run time `at`: logged with the run (its
    /// replay stops being exact there) and told to the front end.
    fn clock_switched(&mut self, clock: ClockKind, at: Nanos) {
        if let Some(run) = self.log.runs.last_mut() {
            run.clock_switches_ns.push(at.0);
        }
        self.save_log();
        let _ = self.tx.send(Telemetry::ClockSwitched { at, clock });
    }

    /// `ros2 param set NODE rate_hz HZ` is the lab's rate key: a command, logged (and
    /// recorded as a parameter set: `ros2_sets`). `None`: read-only over ROS 2.
    fn ros2_set_rate(&self) -> Option<ratelab_ros2::bridge::SetNodeRate> {
        let sets = self.ros2_sets.clone();
        ratelab_runtime::graph::lock(&sets).clear();
        self.settings.control.clone().map(|tx| {
            Arc::new(move |node: &str, hz: f64| {
                let node = node.to_string();
                ratelab_runtime::graph::lock(&sets).push((node.clone(), hz));
                tx.send(Control::Apply(Command::SetNodeHz { node, hz }))
                    .map_err(|_| "the lab has ended".to_string())
            }) as ratelab_ros2::bridge::SetNodeRate
        })
    }

    /// This run's recording, when the lab records (`--record`), and the notice its
    /// creation gave (a viewer that could not be spawned).
    fn create_recording(
        &self,
        cfg: &RunConfig,
        brain: &str,
    ) -> Result<(Option<Recording>, Option<String>), String> {
        let Some(path) = self.recording_path() else {
            return Ok((None, None));
        };
        ratelab_recording::check_output_path(&path, self.settings.force)
            .map_err(|e| e.to_string())?;
        let (r, notice) = Recording::create_with(
            &path,
            cfg,
            brain,
            &RecordOptions {
                spawn: self.settings.spawn,
                window: self.settings.record_window,
                ros2_domain: self.settings.ros2.as_ref().map(|(_, o)| o.domain),
                bag: self.settings.ros2.as_ref().and_then(|(_, o)| o.bag.clone()),
            },
            self.settings.force,
        )
        .map_err(|e| e.to_string())?;
        Ok((Some(r), notice))
    }

    pub(super) fn current_policy_spec(&self, initial: &str) -> String {
        let run = self.log.runs.last().expect("a run");
        run.commands
            .iter()
            .rev()
            .find_map(|c| match &c.command {
                Command::SetPolicy { spec } => Some(spec.clone()),
                _ => None,
            })
            .unwrap_or_else(|| initial.to_string())
    }

    /// After a live rate change (`text` says which, `note` the phase it left): how a run
    /// started at the settings now goes — the headless result, which `r` gives — sent as a
    /// notice when it is known, so that a learner knows how long to wait before judging a
    /// rate (a live run carries its old phase and state, and a rate that fails may take
    /// seconds to show it). Computed on a thread of its own, under the virtual clock, for at
    /// most [`JUDGE_FOR`] (or the run's duration), with the brain in use (a Python brain,
    /// or a graph with Python, registered or external nodes, whose code would run a second
    /// time beside the live one, is not judged).
    pub(super) fn judge_fresh_run(&self, cfg: &RunConfig, h: &GraphHandles, text: String) {
        let spec = h.current_spec();
        let open = spec
            .nodes
            .iter()
            .any(|n| n.kind.code() != ratelab_runtime::graph::kind::Code::BuiltIn);
        let policy = self.current_policy_spec(&self.run_policy);
        if open || policy.contains(".py") {
            return;
        }
        // Under the real clock the judge is still a virtual-clock run: said so (a real-clock
        // run's jitter moves its fall, or keeps it up).
        let real = cfg.clock == ClockKind::Real;
        let mut fresh = cfg.clone();
        fresh.graph = spec;
        fresh.clock = ClockKind::Virtual;
        fresh.duration = cfg.duration.min(JUDGE_FOR);
        let tx = self.tx.clone();
        let _ = std::thread::Builder::new()
            .name("judge".into())
            .spawn(move || {
                let Ok(brain) = load_policy(&policy) else {
                    return;
                };
                let Ok(r) = crate::run::run(&fresh, brain, crate::run::RunOptions::new()) else {
                    return;
                };
                let secs = fresh.duration.as_secs_f64();
                let verdict = match (r.metrics.fell_at_s, real) {
                    (Some(t), false) => format!("a fresh run falls at {t:.2} s: judge no sooner"),
                    (None, false) => format!("a fresh run stays up all of its {secs:.0} s"),
                    (Some(t), true) => {
                        format!("a virtual-clock run falls at {t:.2} s (real runs vary)")
                    }
                    (None, true) => {
                        format!(
                            "a virtual-clock run stays up all of its {secs:.0} s (real runs vary)"
                        )
                    }
                };
                let _ = tx.send(Telemetry::Applied(format!("{text} · {verdict}")));
            });
    }

    /// Send the lab the run's status at run time `now`; `exec`: each node's ticks and skipped
    /// ticks, when the virtual clock's executors measure them.
    pub(super) fn status(
        &self,
        now: Nanos,
        paused: bool,
        h: &GraphHandles,
        exec: Option<Vec<(u64, u64)>>,
    ) {
        let next = self.next_spec(h);
        let _ = self.tx.send(Telemetry::Status {
            now,
            paused,
            speed: self.speed,
            // While frozen, what the next run will start with (the deferred changes applied).
            rates: next.nodes.iter().map(|n| n.rate_hz).collect(),
            depths: next.topics.iter().map(|t| t.depth).collect(),
            qos: next.topics.iter().map(|t| t.qos).collect(),
            alive: h
                .liveliness
                .iter()
                .map(|l| l.lease().map(|_| l.status_at(now).alive))
                .collect(),
            policy: h.brain_label(),
            exec,
            topics: Some(Box::new(h.topic_stats_at(now))),
        });
    }

    /// The graph the next run starts with: this run's as it is now, with the changes made
    /// while it was frozen.
    fn next_spec(&self, h: &GraphHandles) -> ratelab_runtime::graph::GraphSpec {
        let mut next = h.current_spec();
        let mut brain = String::new();
        for cmd in &self.next_run {
            let _ = cmd.apply_to_settings(&mut next, &mut brain);
        }
        next
    }

    /// The lab's `k` after the run has ended: nothing to stall (a fault is an event of a run,
    /// not a setting of the next, [`Engine::defer`]).
    pub(super) fn stall_after_end(&self, node: &str) {
        let _ = self.tx.send(Telemetry::Error(format!(
            "stall {}: the run has ended (r starts the next)",
            ratelab_core::text::printable(node)
        )));
    }

    /// A change made while the run is frozen: checked now, applied when the next run starts
    /// (r, R or c), so the keys still work after a fall.
    pub(super) fn defer(&mut self, cmd: Command, h: &GraphHandles) {
        if matches!(cmd, Command::InjectFault { .. } | Command::SetPhase { .. }) {
            // Events of a run, not settings of the next: a new run starts at its settings.
            let _ = self.tx.send(Telemetry::Error(format!(
                "{}: the run has ended (r starts the next)",
                describe(&cmd)
            )));
            return;
        }
        match cmd.validate(&self.next_spec(h)) {
            Ok(()) => {
                let _ = self.tx.send(Telemetry::Applied(format!(
                    "{} (from the next run)",
                    describe(&cmd)
                )));
                self.next_run.push(cmd);
            }
            Err(e) => {
                let _ = self.tx.send(Telemetry::Error(e));
            }
        }
    }

    /// The step telemetry to the front end, muted while a seek back runs the run again.
    pub(super) fn telemetry_observer(&self) -> TelemetryObserver {
        TelemetryObserver(self.tx.clone(), self.muted.clone())
    }

    /// The run went back to `at` and branched ([`Control::Seek`]): its log holds the
    /// commands of the branch, `applied` (what `replay` then gives), and the clock switches
    /// up to `at`.
    pub(super) fn branch_log(&mut self, applied: &[TimedCommand], at: Nanos) {
        if let Some(run) = self.log.runs.last_mut() {
            run.commands = applied.to_vec();
            // Scrubbing runs under the virtual clock: a switch at the instant itself (where
            // a real-clock part began) came after it, and at t = 0 the whole run is the
            // virtual clock's from its start.
            run.clock_switches_ns.retain(|&s| s < at.0);
            if at == Nanos::ZERO {
                run.clock = ClockKind::Virtual;
            }
        }
        self.save_log();
    }

    /// Apply a graph command, logging it at `at`. Returns false when it was refused.
    pub(super) fn apply(
        &mut self,
        cmd: Command,
        at: Nanos,
        h: &GraphHandles,
        recording: &Option<Recording>,
    ) -> bool {
        self.apply_from(cmd, at, h, recording, true)
    }

    /// [`Engine::apply`] of a command that takes effect from the next run (an executor under
    /// the real clock): logged, but no change of this run's (no new segment, no mark).
    pub(super) fn apply_for_next_run(
        &mut self,
        cmd: Command,
        at: Nanos,
        h: &GraphHandles,
        recording: &Option<Recording>,
    ) -> bool {
        self.apply_from(cmd, at, h, recording, false)
    }

    fn apply_from(
        &mut self,
        cmd: Command,
        at: Nanos,
        h: &GraphHandles,
        recording: &Option<Recording>,
        now: bool,
    ) -> bool {
        self.apply_with(cmd, at, recording, now, |c| c.apply(h, at))
    }

    /// Apply `cmd` with `apply` (to the graph's handles, or through the run core), then log
    /// it at `at`, mark it in the recording and tell the front end (`now`: it changes this
    /// run). Returns false when it was refused (the front end is told why).
    pub(super) fn apply_with(
        &mut self,
        cmd: Command,
        at: Nanos,
        recording: &Option<Recording>,
        now: bool,
        apply: impl FnOnce(&Command) -> Result<(), String>,
    ) -> bool {
        // A rate set from ROS 2 arrives as the rate key's command: told apart here.
        let from_ros2 = match &cmd {
            Command::SetNodeHz { node, hz } => {
                let mut sets = ratelab_runtime::graph::lock(&self.ros2_sets);
                let found = sets.iter().position(|(n, h)| n == node && h == hz);
                found.map(|i| sets.remove(i)).is_some()
            }
            _ => false,
        };
        match apply(&cmd) {
            Ok(()) => {
                // The fault as it takes effect, as the graph's fault book holds it, and said
                // so: a logged `policy@9.36+0.5` applied before the instant at 9.38 s takes
                // effect there, until 9.86 s (the lab's `k` is booked at that instant already).
                let faulted = match &cmd {
                    Command::InjectFault { fault } => ratelab_runtime::command::parse_fault(fault)
                        .ok()
                        .and_then(|f| ratelab_runtime::command::taking_effect(&f, at).ok()),
                    _ => None,
                };
                let text = match &faulted {
                    Some(f) => format!("fault → {}", ratelab_core::text::printable(&f.to_string())),
                    None => describe(&cmd),
                };
                if let Some(r) = recording {
                    record_change(r, at, &cmd, (&text, faulted.as_ref()), from_ros2);
                }
                self.log
                    .runs
                    .last_mut()
                    .expect("a run")
                    .commands
                    .push(TimedCommand {
                        at_ns: at.0,
                        command: cmd,
                    });
                self.save_log();
                if now {
                    if let Some(f) = faulted {
                        let _ = self.tx.send(Telemetry::Faulted(f));
                    }
                    let _ = self.tx.send(Telemetry::Changed { at, text });
                }
                true
            }
            Err(e) => {
                let _ = self.tx.send(Telemetry::Error(e));
                false
            }
        }
    }
}

/// Finish a run's recording (its summary `metrics`, its end `end`); a run that ends for a
/// save's reload (`next`) says so at its end: the saved code runs from t = 0 in the next.
fn finish_recording(r: &Recording, next: &Next, metrics: &Metrics, end: &RunEnd) {
    if let Next::Reload(_) = next {
        let text = "reloaded: the saved code runs again from t = 0, in the next recording";
        r.reloaded(end.at, text);
    }
    let _ = r.finish(metrics, end);
}

/// Record a command applied at run time `at` that the graph's own rows do not show as an
/// event with a mark: a brain swap (`text`), a fault injected (the stall key `k`; `faulted`,
/// as it took effect, as the run's fault book holds it), a rate set from ROS 2
/// (`from_ros2`). Rates, depths and QoS changed from the keys are the graph's, recorded by
/// its observer.
fn record_change(
    r: &Recording,
    at: Nanos,
    cmd: &Command,
    (text, faulted): (&str, Option<&ratelab_core::qos::Fault>),
    from_ros2: bool,
) {
    match cmd {
        Command::SetPolicy { .. } => r.change(at, text),
        Command::InjectFault { .. } => {
            if let Some(f) = faulted {
                r.injected_fault(at, f);
            }
        }
        Command::SetNodeHz { node, hz } if from_ros2 => r.parameter_set(at, node, *hz),
        _ => {}
    }
}

/// The summary of a live run that ended at `end.at` (its duration, for an open-ended run).
pub(super) fn live_metrics(
    cfg: &RunConfig,
    h: &GraphHandles,
    end: &RunEnd,
    ticks: &[u64],
    timing: Option<Vec<NodeTiming>>,
    exec: Option<ratelab_core::executor::ExecFigures>,
) -> Metrics {
    summarize(
        &RunConfig {
            duration: end.at,
            ..cfg.clone()
        },
        h,
        end,
        ticks,
        timing,
        exec,
    )
}
