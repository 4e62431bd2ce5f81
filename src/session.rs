//! Live sessions: the graph driven by commands while it runs, for the lab.
//!
//! An engine thread owns the graph and talks to its front end (the terminal lab) over
//! crossbeam channels: [`Control`] in, [`Telemetry`] out. The engine never waits for the
//! front end (telemetry goes into an unbounded channel that the front end drains each
//! frame), and the front end never blocks the graph.
//!
//! Under the virtual clock the engine works one *instant* at a time (every tick due at the
//! same virtual time), paced against the wall clock for display at a chosen speed. Pacing
//! decides only *when* an instant runs, never its order, so it cannot change a result.
//! A rate, depth or brain change is applied between instants and logged with the virtual
//! time of the next instant. The [`SessionLog`] (JSON) therefore replays exactly:
//! [`replay_run`] re-runs a logged run headless and reproduces its metrics byte for byte.
//! Under the real clock changes are applied at once (from each node's next tick); such
//! runs are logged but, being concurrent, cannot be replayed exactly.

use crate::checkpoint::load_policy;
use crate::config::{ClockKind, RunConfig};
use crate::graph::{Graph, GraphHandles, StepObserver};
use crate::metrics::{Metrics, StepRecord};
use crate::node::Flow;
use crate::policy::BrainSlot;
use crate::recording::{RecordOptions, Recording};
use crate::run::{build_graph, summarize, Command, RunOptions, TimedCommand};
use crate::scheduler::{run_real, EndReason, RealOptions, RunEnd, StopFlag, VirtualScheduler};
use crate::time::Nanos;
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// "Run until stopped": the duration of an open-ended lab run.
pub const UNBOUNDED: Nanos = Nanos(u64::MAX / 4);

/// Virtual-clock pacing: wall seconds per virtual second, or as fast as possible.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Speed {
    /// Virtual time runs at this multiple of wall time.
    Times(f64),
    /// No pacing.
    Max,
}

/// The speed ladder of the lab's `<`/`>` keys.
pub const SPEEDS: [Speed; 7] = [
    Speed::Times(0.25),
    Speed::Times(0.5),
    Speed::Times(1.0),
    Speed::Times(2.0),
    Speed::Times(4.0),
    Speed::Times(8.0),
    Speed::Max,
];

impl std::fmt::Display for Speed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Speed::Times(x) => write!(f, "×{x}"),
            Speed::Max => f.write_str("max"),
        }
    }
}

/// What the front end asks of the engine.
#[derive(Clone, Debug, PartialEq)]
pub enum Control {
    /// Change the graph (rates, depth, brain).
    Apply(Command),
    /// Pause or resume.
    TogglePause,
    /// While paused (virtual clock): run until the next actuator tick.
    Step,
    /// Start a new run with the current settings: same seed, or the next one.
    Reset {
        /// Use `seed + 1`.
        next_seed: bool,
    },
    /// Restart the run with the current settings under the other clock.
    SwitchClock,
    /// Virtual pacing.
    SetSpeed(Speed),
    /// End the session.
    Quit,
}

/// What the engine reports.
#[derive(Clone, Debug)]
pub enum Telemetry {
    /// A run started.
    Started {
        /// Its settings (rates, depth and clock as they start).
        cfg: RunConfig,
        /// The brain's label.
        policy: String,
        /// Where it is being recorded, if anywhere.
        recording: Option<PathBuf>,
    },
    /// One actuator tick.
    Step(StepRecord),
    /// One node tick under the real clock: node index (0 sensor, 1 policy, 2 actuator),
    /// run time and lateness.
    NodeTick {
        /// Node index.
        node: usize,
        /// Run time.
        now: Nanos,
        /// Actual − scheduled.
        lateness: Nanos,
    },
    /// Periodic status.
    Status {
        /// Run time now (virtual: the last instant run).
        now: Nanos,
        /// Paused?
        paused: bool,
        /// Virtual pacing.
        speed: Speed,
        /// Set rates: sensor, control, actuator.
        rates: [f64; 3],
        /// Current depth of both topics.
        depth: usize,
        /// The brain's label.
        policy: String,
    },
    /// A command was applied (for the front end's log line).
    Applied(String),
    /// The run ended (fall, duration, node failure); the state is frozen until reset or quit.
    Ended {
        /// Its summary.
        metrics: Metrics,
        /// How it ended.
        reason: EndReason,
    },
    /// Something went wrong that the user should read (one line).
    Error(String),
}

/// One run of a session, as logged for replay.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LoggedRun {
    /// `virtual` or `real` (only virtual runs replay exactly).
    pub clock: ClockKind,
    /// Seed.
    pub seed: u64,
    /// Rates at the start, Hz.
    pub sensor_hz: f64,
    /// Control rate at the start, Hz.
    pub control_hz: f64,
    /// Actuator rate, Hz.
    pub actuator_hz: f64,
    /// Depth at the start.
    pub queue_depth: usize,
    /// Brain at the start.
    pub policy: String,
    /// Run time at which the run ended (the last instant run), ns.
    pub end_ns: u64,
    /// The commands, in order, with the virtual time they took effect.
    pub commands: Vec<TimedCommand>,
    /// The summary at the end, as the live run measured it.
    pub metrics: Option<Metrics>,
}

impl LoggedRun {
    /// The settings to replay it with: duration = its end time.
    pub fn config(&self) -> RunConfig {
        RunConfig {
            clock: self.clock,
            seed: self.seed,
            sensor_hz: self.sensor_hz,
            control_hz: self.control_hz,
            actuator_hz: self.actuator_hz,
            queue_depth: self.queue_depth,
            duration: Nanos(self.end_ns),
            ..RunConfig::default()
        }
    }
}

/// A session's command log: every run, in order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SessionLog {
    /// Format version.
    pub version: u32,
    /// The runs.
    pub runs: Vec<LoggedRun>,
}

/// Why a replay could not run.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// Unreadable file.
    #[error("cannot read session {0}")]
    Read(String),
    /// Not a session log.
    #[error("{path}: not a ratelab session log ({detail})")]
    Parse {
        /// The file.
        path: String,
        /// The parser's complaint.
        detail: String,
    },
    /// Real-clock runs are not reproducible.
    #[error("run {0} used the real clock, which cannot be replayed exactly")]
    RealClock(usize),
    /// A run could not start.
    #[error(transparent)]
    Run(#[from] crate::run::RunError),
    /// The brain could not be loaded.
    #[error(transparent)]
    Policy(#[from] crate::checkpoint::PolicyError),
}

impl SessionLog {
    /// Read a session log (JSON).
    ///
    /// # Errors
    /// [`ReplayError`] when unreadable or malformed.
    pub fn load(path: &std::path::Path) -> Result<Self, ReplayError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| ReplayError::Read(format!("{}: {e}", path.display())))?;
        serde_json::from_str(&text).map_err(|e| ReplayError::Parse {
            path: path.display().to_string(),
            detail: e.to_string(),
        })
    }

    /// Write it (pretty JSON), atomically (write then rename).
    ///
    /// # Errors
    /// The I/O error.
    pub fn save(&self, path: &std::path::Path) -> std::io::Result<()> {
        let tmp = path.with_extension("json.part");
        std::fs::write(
            &tmp,
            serde_json::to_string_pretty(self).expect("serializable") + "\n",
        )?;
        std::fs::rename(tmp, path)
    }
}

/// Re-run logged run `index` headless under the virtual clock.
///
/// # Errors
/// [`ReplayError`]; real-clock runs are refused.
pub fn replay_run(log: &SessionLog, index: usize) -> Result<Metrics, ReplayError> {
    let r = &log.runs[index];
    if r.clock != ClockKind::Virtual {
        return Err(ReplayError::RealClock(index + 1));
    }
    let brain = load_policy(&r.policy)?;
    let opts = RunOptions {
        commands: r.commands.clone(),
        keep_trace: false,
        ..RunOptions::default()
    };
    Ok(crate::run::run(&r.config(), brain, opts)?.metrics)
}

/// How the lab's engine starts.
#[derive(Clone, Debug)]
pub struct SessionSettings {
    /// The first run's settings (`duration` may be [`UNBOUNDED`]).
    pub cfg: RunConfig,
    /// The first run's brain spec.
    pub policy: String,
    /// The checkpoint the `p` key swaps with `scripted`, if one was given.
    pub alt_policy: Option<String>,
    /// Record each run (the first to this path; later ones get `-2`, `-3`, … suffixes).
    pub record: Option<PathBuf>,
    /// Stream recordings to a viewer as well.
    pub spawn: bool,
    /// Where to save the session log after every run and command.
    pub session_file: Option<PathBuf>,
    /// Start paused.
    pub start_paused: bool,
    /// Initial virtual speed.
    pub speed: Speed,
}

/// Streams step records to the front end.
struct TelemetryObserver(Sender<Telemetry>);

impl StepObserver for TelemetryObserver {
    fn on_step(&mut self, rec: &StepRecord) {
        let _ = self.0.send(Telemetry::Step(*rec));
    }
}

/// The engine: run sessions until [`Control::Quit`]; returns the session log.
pub struct Engine {
    settings: SessionSettings,
    rx: Receiver<Control>,
    tx: Sender<Telemetry>,
    log: SessionLog,
    speed: Speed,
    run_index: usize,
}

/// What ended a run from the engine's side.
enum Next {
    Reset { next_seed: bool },
    SwitchClock,
    Quit,
}

impl Engine {
    /// A new engine; call [`Engine::run`] on its own thread.
    pub fn new(settings: SessionSettings, rx: Receiver<Control>, tx: Sender<Telemetry>) -> Self {
        let speed = settings.speed;
        Self {
            settings,
            rx,
            tx,
            log: SessionLog {
                version: 1,
                runs: Vec::new(),
            },
            speed,
            run_index: 0,
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
                Ok((next, last)) => {
                    // The next run keeps the settings as the user left them.
                    cfg.sensor_hz = last.sensor_hz;
                    cfg.control_hz = last.control_hz;
                    cfg.queue_depth = last.queue_depth;
                    policy = last.policy;
                    next
                }
                Err(e) => {
                    let _ = self.tx.send(Telemetry::Error(e));
                    // Wait for the user's decision.
                    match self.rx.recv() {
                        Ok(Control::Reset { next_seed }) => Next::Reset { next_seed },
                        Ok(Control::SwitchClock) => Next::SwitchClock,
                        _ => Next::Quit,
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
            }
        }
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

    /// One run; returns what the user asked next and the settings it ended with.
    fn one_run(&mut self, cfg: &RunConfig, policy: &str) -> Result<(Next, LoggedRun), String> {
        self.run_index += 1;
        let brain = load_policy(policy).map_err(|e| e.to_string())?;
        let recording = match self.recording_path() {
            Some(path) => {
                crate::recording::check_output_path(&path, true).map_err(|e| e.to_string())?;
                let (r, notice) = Recording::create(
                    &path,
                    cfg,
                    &brain.label(),
                    &RecordOptions {
                        spawn: self.settings.spawn,
                    },
                )
                .map_err(|e| e.to_string())?;
                if let Some(n) = notice {
                    let _ = self.tx.send(Telemetry::Error(n));
                }
                Some(r)
            }
            None => None,
        };
        let mut observers: Vec<Box<dyn StepObserver>> =
            vec![Box::new(TelemetryObserver(self.tx.clone()))];
        if let Some(r) = &recording {
            observers.push(r.observer());
        }
        let slot = BrainSlot::new(brain);
        let graph = build_graph(cfg, slot, false, observers).map_err(|e| e.to_string())?;
        let _ = self.tx.send(Telemetry::Started {
            cfg: cfg.clone(),
            policy: graph.handles.brain.label(),
            recording: recording.as_ref().map(|r| r.path().to_path_buf()),
        });
        self.log.runs.push(LoggedRun {
            clock: cfg.clock,
            seed: cfg.seed,
            sensor_hz: cfg.sensor_hz,
            control_hz: cfg.control_hz,
            actuator_hz: cfg.actuator_hz,
            queue_depth: cfg.queue_depth,
            policy: policy.to_string(),
            end_ns: 0,
            commands: Vec::new(),
            metrics: None,
        });
        self.save_log();
        let handles = graph.handles.clone();
        let (next, end, timing) = match cfg.clock {
            ClockKind::Virtual => {
                let (next, end) = self.virtual_run(cfg, graph, &recording);
                (next, end, None)
            }
            ClockKind::Real => self.real_run(cfg, graph, &recording),
        };
        let metrics = live_metrics(cfg, &handles, &end, timing);
        if let Some(r) = &recording {
            let _ = r.finish(&metrics, &end);
        }
        let current = self.log.runs.last_mut().expect("pushed above");
        current.end_ns = end.at.0;
        current.metrics = Some(metrics);
        let mut last = current.clone();
        last.sensor_hz = handles.sensor_rate.hz();
        last.control_hz = handles.control_rate.hz();
        last.queue_depth = handles.obs.stats().depth;
        last.policy = self.current_policy_spec(policy);
        self.save_log();
        Ok((next, last))
    }

    fn current_policy_spec(&self, initial: &str) -> String {
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

    fn status(&self, now: Nanos, paused: bool, h: &GraphHandles) {
        let _ = self.tx.send(Telemetry::Status {
            now,
            paused,
            speed: self.speed,
            rates: [
                h.sensor_rate.hz(),
                h.control_rate.hz(),
                h.actuator_rate.hz(),
            ],
            depth: h.obs.stats().depth,
            policy: h.brain.label(),
        });
    }

    /// Apply a graph command, logging it at `at`. Returns false when it was refused.
    fn apply(
        &mut self,
        cmd: Command,
        at: Nanos,
        h: &GraphHandles,
        recording: &Option<Recording>,
    ) -> bool {
        match cmd.apply(h) {
            Ok(()) => {
                let text = describe(&cmd);
                if let Some(r) = recording {
                    if let Command::SetPolicy { .. } = cmd {
                        r.change(at, &text);
                    }
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
                let _ = self.tx.send(Telemetry::Applied(text));
                true
            }
            Err(e) => {
                let _ = self.tx.send(Telemetry::Error(e));
                false
            }
        }
    }

    fn virtual_run(
        &mut self,
        cfg: &RunConfig,
        graph: Graph,
        recording: &Option<Recording>,
    ) -> (Next, RunEnd) {
        let Graph { mut nodes, handles } = graph;
        let mut sched = VirtualScheduler::new(&nodes);
        let mut paused = self.settings.start_paused;
        let mut step_pending = false;
        let mut ended: Option<RunEnd> = None;
        // Pacing anchor: virtual time `anchor_v` corresponds to wall instant `anchor_w`.
        let mut anchor_v = Nanos::ZERO;
        let mut anchor_w = Instant::now();
        let mut last_status = Instant::now() - Duration::from_secs(1);
        loop {
            // Controls, between instants.
            loop {
                let msg = if paused || ended.is_some() {
                    match self.rx.recv_timeout(Duration::from_millis(30)) {
                        Ok(m) => m,
                        Err(RecvTimeoutError::Timeout) => break,
                        Err(RecvTimeoutError::Disconnected) => {
                            return (Next::Quit, self.end_now(&sched, ended))
                        }
                    }
                } else {
                    match self.rx.try_recv() {
                        Ok(m) => m,
                        Err(_) => break,
                    }
                };
                match msg {
                    Control::Apply(cmd) => {
                        if ended.is_none() {
                            let at = sched.next_due().unwrap_or(sched.now());
                            self.apply(cmd, at, &handles, recording);
                        }
                    }
                    Control::TogglePause => {
                        paused = !paused;
                        anchor_v = sched.now();
                        anchor_w = Instant::now();
                    }
                    Control::Step => {
                        if paused {
                            step_pending = true;
                        }
                    }
                    Control::SetSpeed(s) => {
                        self.speed = s;
                        anchor_v = sched.now();
                        anchor_w = Instant::now();
                    }
                    Control::Reset { next_seed } => {
                        return (Next::Reset { next_seed }, self.end_now(&sched, ended))
                    }
                    Control::SwitchClock => {
                        return (Next::SwitchClock, self.end_now(&sched, ended))
                    }
                    Control::Quit => return (Next::Quit, self.end_now(&sched, ended)),
                }
                if step_pending {
                    break;
                }
            }
            if last_status.elapsed() >= Duration::from_millis(33) {
                self.status(sched.now(), paused, &handles);
                last_status = Instant::now();
            }
            if ended.is_some() || (paused && !step_pending) {
                continue;
            }
            // Which instants may run now?
            let target = if step_pending {
                None // one control step: until the actuator ticks
            } else {
                match self.speed {
                    Speed::Max => None,
                    Speed::Times(x) => {
                        Some(anchor_v + Nanos((anchor_w.elapsed().as_nanos() as f64 * x) as u64))
                    }
                }
            };
            let budget = Instant::now();
            while let Some(due) = sched.next_due() {
                if due > cfg.duration {
                    ended = Some(RunEnd {
                        at: cfg.duration.min(sched.now()),
                        reason: EndReason::Duration,
                    });
                    break;
                }
                if target.is_some_and(|t| due > t) {
                    break;
                }
                let actuator_ticked = match run_instant(&mut sched, &mut nodes) {
                    InstantOutcome::Ran { actuator } => actuator,
                    InstantOutcome::Stopped => {
                        ended = Some(RunEnd {
                            at: sched.now(),
                            reason: EndReason::NodeStopped,
                        });
                        break;
                    }
                    InstantOutcome::Failed(reason) => {
                        ended = Some(RunEnd {
                            at: sched.now(),
                            reason,
                        });
                        break;
                    }
                };
                if step_pending && actuator_ticked {
                    step_pending = false;
                    break;
                }
                // Stay responsive at max speed: come back for controls every few ms.
                if budget.elapsed() > Duration::from_millis(8) {
                    break;
                }
            }
            if let Some(end) = &ended {
                let metrics = live_metrics(cfg, &handles, end, None);
                self.status(sched.now(), paused, &handles);
                let _ = self.tx.send(Telemetry::Ended {
                    metrics,
                    reason: end.reason.clone(),
                });
                continue;
            }
            // Sleep until the next instant is due on the wall (or a few ms at most).
            if let (Some(due), Speed::Times(x)) = (sched.next_due(), self.speed) {
                if !step_pending {
                    let wait_v = due.saturating_sub(anchor_v).0 as f64 / x;
                    let wake = anchor_w + Duration::from_nanos(wait_v as u64);
                    let now = Instant::now();
                    if wake > now {
                        std::thread::sleep((wake - now).min(Duration::from_millis(10)));
                    }
                }
            }
        }
    }

    fn end_now(&self, sched: &VirtualScheduler, ended: Option<RunEnd>) -> RunEnd {
        ended.unwrap_or(RunEnd {
            at: sched.now(),
            reason: EndReason::Interrupted,
        })
    }

    fn real_run(
        &mut self,
        cfg: &RunConfig,
        graph: Graph,
        recording: &Option<Recording>,
    ) -> (Next, RunEnd, Option<Vec<crate::metrics::NodeTiming>>) {
        let Graph { nodes, handles } = graph;
        if let Some(Err(e)) = cfg.rt_priority.map(crate::realtime::probe_fifo) {
            // Told now, not only when the run ends: node threads inherit this thread's
            // privileges, so they will be refused the same way.
            let _ = self.tx.send(Telemetry::Applied(format!(
                "warning: node threads keep their default policy: {e}"
            )));
        }
        let stop = StopFlag::new();
        let pause = Arc::new(AtomicBool::new(self.settings.start_paused));
        let tx = self.tx.clone();
        let rec = recording.clone();
        let names = ["sensor", "policy", "actuator"];
        let opts = RealOptions {
            spin_margin: cfg.spin_margin,
            phase_offsets: cfg.phase_offsets.to_vec(),
            rt_priority: cfg.rt_priority,
            on_tick: Some(Arc::new(move |name: &str, now: Nanos, lateness: Nanos| {
                let node = names.iter().position(|n| *n == name).unwrap_or(0);
                let _ = tx.send(Telemetry::NodeTick {
                    node,
                    now,
                    lateness,
                });
                if let Some(r) = &rec {
                    r.node_tick(name, now, lateness);
                }
            })),
            pause: Some(pause.clone()),
        };
        let start = Instant::now();
        let runner = {
            let stop = stop.clone();
            let duration = cfg.duration;
            std::thread::Builder::new()
                .name("real-clock".into())
                .spawn(move || run_real(nodes, duration, &stop, &opts))
                .expect("spawning the real-clock runner")
        };
        let now = || Nanos::from(start.elapsed());
        let mut last_status = Instant::now();
        let mut result: Option<RunEnd> = None;
        let mut timing = None;
        let mut runner = Some(runner);
        loop {
            if result.is_none() && runner.as_ref().is_some_and(|r| r.is_finished()) {
                let run = runner
                    .take()
                    .expect("checked")
                    .join()
                    .expect("runner thread");
                let end = run.end.clone();
                timing = Some(run.timing);
                let metrics = live_metrics(cfg, &handles, &end, timing.clone());
                let _ = self.tx.send(Telemetry::Ended {
                    metrics,
                    reason: end.reason.clone(),
                });
                result = Some(end);
            }
            let next = match self.rx.recv_timeout(Duration::from_millis(30)) {
                Ok(Control::Apply(cmd)) => {
                    if result.is_none() {
                        self.apply(cmd, now(), &handles, recording);
                    }
                    None
                }
                Ok(Control::TogglePause) => {
                    let p = !pause.load(Ordering::SeqCst);
                    pause.store(p, Ordering::SeqCst);
                    None
                }
                Ok(Control::Step | Control::SetSpeed(_)) => {
                    let _ = self.tx.send(Telemetry::Error(
                        "single-step and speed apply to the virtual clock only".into(),
                    ));
                    None
                }
                Ok(Control::Reset { next_seed }) => Some(Next::Reset { next_seed }),
                Ok(Control::SwitchClock) => Some(Next::SwitchClock),
                Ok(Control::Quit) | Err(RecvTimeoutError::Disconnected) => Some(Next::Quit),
                Err(RecvTimeoutError::Timeout) => None,
            };
            if let Some(next) = next {
                stop.stop();
                let end = match (result, runner.take()) {
                    (Some(end), _) => end,
                    (None, Some(r)) => match r.join() {
                        Ok(run) => {
                            timing = Some(run.timing);
                            run.end
                        }
                        Err(_) => RunEnd {
                            at: now(),
                            reason: EndReason::Interrupted,
                        },
                    },
                    (None, None) => RunEnd {
                        at: now(),
                        reason: EndReason::Interrupted,
                    },
                };
                return (next, end, timing);
            }
            if last_status.elapsed() >= Duration::from_millis(33) {
                self.status(now(), pause.load(Ordering::SeqCst), &handles);
                last_status = Instant::now();
            }
        }
    }
}

/// What running one virtual instant did.
#[derive(Debug, PartialEq)]
enum InstantOutcome {
    /// Every tick due ran; whether the actuator was among them.
    Ran {
        /// The actuator ticked.
        actuator: bool,
    },
    /// A node stopped the graph (the fall).
    Stopped,
    /// A node panicked: the graph stops and the lab names the node.
    Failed(EndReason),
}

/// Run every tick due at the next instant. A panicking node is caught and reported.
fn run_instant(
    sched: &mut VirtualScheduler,
    nodes: &mut [Box<dyn crate::node::Node>],
) -> InstantOutcome {
    let Some(t) = sched.next_due() else {
        return InstantOutcome::Ran { actuator: false };
    };
    let mut actuator = false;
    while sched.next_due() == Some(t) {
        let name = sched
            .next_node()
            .map(|i| nodes[i].name().to_string())
            .unwrap_or_default();
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| sched.tick_next(nodes))) {
            Err(p) => {
                let message = crate::scheduler::panic_message(&*p);
                return InstantOutcome::Failed(EndReason::NodeFailed {
                    node: name,
                    message,
                });
            }
            Ok(None) => break,
            Ok(Some((_, i, flow))) => {
                actuator |= nodes[i].name() == "actuator";
                if flow == Flow::Stop {
                    return InstantOutcome::Stopped;
                }
            }
        }
    }
    InstantOutcome::Ran { actuator }
}

/// The summary of a live run that ended at `end.at` (its duration, for an open-ended run).
fn live_metrics(
    cfg: &RunConfig,
    h: &GraphHandles,
    end: &RunEnd,
    timing: Option<Vec<crate::metrics::NodeTiming>>,
) -> Metrics {
    summarize(
        &RunConfig {
            duration: end.at,
            ..cfg.clone()
        },
        h,
        end,
        timing,
    )
}

/// A command in words, for logs.
pub fn describe(cmd: &Command) -> String {
    match cmd {
        Command::SetControlHz { hz } => format!("control rate → {hz} Hz"),
        Command::SetSensorHz { hz } => format!("sensor rate → {hz} Hz"),
        Command::SetQueueDepth { depth } => format!("queue depth → {depth}"),
        Command::SetPolicy { spec } => format!("brain → {spec}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::node::Node;
    use crate::rate::Rate;

    struct Flaky(Rate, &'static str, bool);
    impl Node for Flaky {
        fn name(&self) -> &str {
            self.1
        }
        fn priority(&self) -> u8 {
            u8::from(self.2)
        }
        fn rate(&self) -> &Rate {
            &self.0
        }
        fn tick(&mut self, now: Nanos) -> Flow {
            assert!(!(self.2 && now > Nanos::ZERO), "policy exploded");
            Flow::Continue
        }
    }

    #[test]
    fn a_panicking_node_is_named_not_fatal() {
        let mut nodes: Vec<Box<dyn Node>> = vec![
            Box::new(Flaky(Rate::new(50.0).unwrap(), "sensor", false)),
            Box::new(Flaky(Rate::new(50.0).unwrap(), "policy", true)),
        ];
        let mut sched = VirtualScheduler::new(&nodes);
        assert_eq!(
            run_instant(&mut sched, &mut nodes),
            InstantOutcome::Ran { actuator: false }
        );
        match run_instant(&mut sched, &mut nodes) {
            InstantOutcome::Failed(EndReason::NodeFailed { node, message }) => {
                assert_eq!(node, "policy");
                assert!(message.contains("policy exploded"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }
}
