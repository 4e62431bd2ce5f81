//! The session log (JSON): every run of a lab session with the commands applied and the
//! virtual instants they took effect at, and its exact replay.

use crate::run::TimedCommand;
use crate::run_spec::RunSpec;
use crate::start::StartOptions;
use ratelab_core::metrics::Metrics;
use ratelab_core::plant::ACTUATOR_HZ;
use ratelab_core::time::Nanos;
use ratelab_core::time::MAX_DURATION;
use ratelab_runtime::command::Command;
use ratelab_runtime::config::{ClockKind, RunConfig};
use ratelab_runtime::scheduler::StopFlag;
use ratelab_runtime::setting::Speech;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The session-log format this version writes. Version 1 (before graphs were data) named
/// the chapter's rates and depth; version 2 stores each run's graph as a graph file;
/// version 3 books an injected fault from the instant it took effect (before, at the time
/// it was given: a replay of an older log books it so, [`Command::InjectFaultAsGiven`]).
pub const SESSION_VERSION: u32 = 3;

/// A session log larger than this is refused before it is read, bytes (a long lab session
/// logs kilobytes).
pub const MAX_SESSION_BYTES: u64 = 4 * 1024 * 1024;

/// The most runs, and the most commands per run, a session log may hold.
pub const MAX_LOGGED: usize = 10_000;

/// One run of a session, as logged for replay.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoggedRun {
    /// `virtual` or `real`: the clock the run started under (only virtual runs replay
    /// exactly).
    pub clock: ClockKind,
    /// Run times at which the run went on under the other clock (the lab's `c` on a run
    /// still going), ns, in order: the first switches from `clock`, the next back, and so
    /// on. A run with a real-clock part does not replay exactly.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clock_switches_ns: Vec<u64>,
    /// Seed.
    pub seed: u64,
    /// Version 2: the graph, as a graph file (TOML), with the rates and depths the run
    /// started with: its contents, so a replay does not depend on the file it came from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph: Option<String>,
    /// Version 1 only: the sensor rate at the start, Hz.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_hz: Option<f64>,
    /// Version 1 only: the control rate at the start, Hz.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub control_hz: Option<f64>,
    /// Version 1 only: the actuator rate, Hz (50).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actuator_hz: Option<f64>,
    /// Version 1 only: both topics' depth at the start.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub queue_depth: Option<usize>,
    /// First deadline of each node, ns (phase offsets), when any was set.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub phase_offsets_ns: Vec<u64>,
    /// Faults injected (`--stall`, `--kill`), when any was.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub faults: Vec<ratelab_core::qos::Fault>,
    /// Brain at the start.
    pub policy: String,
    /// Run time at which the run ended (the last instant run), ns.
    pub end_ns: u64,
    /// The commands, in order, with the virtual time they took effect. One after `end_ns`
    /// was made after the run's last instant (while paused, then a restart or quit): it
    /// changed the settings the run ended with, not a tick of it ([`LoggedRun::after_end`]).
    pub commands: Vec<TimedCommand>,
    /// The summary at the end, as the live run measured it.
    pub metrics: Option<Metrics>,
    /// Read from a log of version 2 or before, whose runs booked an injected fault at the
    /// time it was given (`SESSION_VERSION`); never written.
    #[serde(skip)]
    pub faults_as_given: bool,
}

impl LoggedRun {
    /// The commands applied between instants of the run, in order: those at or before its
    /// end.
    pub fn applied(&self) -> &[TimedCommand] {
        &self.commands[..self.after_end_from()]
    }

    /// The commands made after the run's last instant (while paused, then a restart or
    /// quit): logged for the instant after it, which never ran. They changed the settings
    /// the run ended with (its summary's end rates), not a tick: a replay applies them once
    /// the run has ended ([`crate::run::RunOptions::after_end`]), as the live run did.
    pub fn after_end(&self) -> &[TimedCommand] {
        &self.commands[self.after_end_from()..]
    }

    fn after_end_from(&self) -> usize {
        self.commands.partition_point(|c| c.at_ns <= self.end_ns)
    }

    /// A run about to start with `cfg` and brain `policy` (no commands, no end yet).
    pub fn starting(cfg: &RunConfig, policy: &str) -> LoggedRun {
        LoggedRun {
            clock: cfg.clock,
            clock_switches_ns: Vec::new(),
            seed: cfg.seed,
            graph: Some(cfg.graph.to_toml()),
            sensor_hz: None,
            control_hz: None,
            actuator_hz: None,
            queue_depth: None,
            phase_offsets_ns: cfg.phase_offsets.iter().map(|n| n.0).collect(),
            faults: cfg.faults.clone(),
            policy: policy.to_string(),
            end_ns: 0,
            commands: Vec::new(),
            metrics: None,
            faults_as_given: false,
        }
    }

    /// The run to replay it with, as every front end describes a run ([`RunSpec`]): its
    /// graph's text (version 2) or the chapter's graph at its logged rates and depth
    /// (version 1), its seed, clock, phase offsets, faults and brain, its duration its end
    /// time, and its commands at their times (those after its end applied once it has
    /// ended). Checks here what only the log can get wrong, naming the log's fields; the
    /// rest is [`RunSpec::config`]'s ([`LoggedRun::config`]). `origin` names the run in
    /// errors (`FILE: run N`).
    ///
    /// # Errors
    /// [`ReplayError::Invalid`] for a run with both or neither graph forms, an actuator rate
    /// other than the chapter's, a phase offset of a second or more, an end past the
    /// longest run, too many faults, or kills listed before stalls.
    pub fn spec(&self, origin: &str) -> Result<RunSpec, ReplayError> {
        let bad = |field: &str, reason: String| {
            ReplayError::Invalid(format!("{origin}: {field}: {reason}"))
        };
        let mut spec = RunSpec {
            clock: self.clock,
            seed: self.seed,
            policy: self.policy.clone(),
            commands: self.commands.clone(),
            ..RunSpec::default()
        };
        if self.faults_as_given {
            // Booked as that run booked them (its summary lists their given times).
            for c in &mut spec.commands {
                if let Command::InjectFault { fault } = &c.command {
                    let fault = fault.clone();
                    c.command = Command::InjectFaultAsGiven { fault };
                }
            }
        }
        match (&self.graph, self.sensor_hz, self.control_hz, self.queue_depth) {
            (Some(text), None, None, None) => {
                spec.graph.inline = Some((text.clone(), "graph".into()));
            }
            (None, Some(sensor), Some(control), Some(depth)) => {
                if self.actuator_hz.is_some_and(|a| a != ACTUATOR_HZ) {
                    return Err(bad("actuator_hz", format!("must be {ACTUATOR_HZ} Hz")));
                }
                spec.sensor_hz = Some(sensor);
                spec.control_hz = Some(control);
                spec.queue_depth = Some(depth);
            }
            _ => {
                return Err(bad(
                    "graph",
                    "a run has either a graph (version 2) or sensor_hz, control_hz and queue_depth (version 1)".into(),
                ))
            }
        }
        if let Some(&o) = self
            .phase_offsets_ns
            .iter()
            .find(|&&o| o >= Nanos::SECOND.0)
        {
            return Err(bad(
                "phase_offsets_ns",
                format!("{o} ns is not below one second"),
            ));
        }
        // Exact: a whole number of ns below a second goes to ms and back unchanged (tests).
        spec.phase_offset_ms = self
            .phase_offsets_ns
            .iter()
            .map(|&n| n as f64 / 1e6)
            .collect();
        if self.end_ns > MAX_DURATION.0 {
            return Err(bad(
                "end_ns",
                format!(
                    "{} ns is longer than the longest run ({MAX_DURATION})",
                    self.end_ns
                ),
            ));
        }
        // A run that ended before its first instant keeps the default duration: its
        // settings are checked all the same, and there is nothing to replay (`replay_run`).
        spec.duration_ns = (self.end_ns > 0).then_some(self.end_ns);
        if self.faults.len() > ratelab_runtime::config::MAX_FAULTS {
            return Err(bad(
                "faults",
                ratelab_core::limits::refusal(
                    format_args!("at most {} faults", ratelab_runtime::config::MAX_FAULTS),
                    "MAX_FAULTS",
                ),
            ));
        }
        let (stalls, kills) = self
            .faults
            .iter()
            .cloned()
            .partition(|f| f.duration.is_some());
        (spec.graph.stalls, spec.graph.kills) = (stalls, kills);
        if spec.graph.faults() != self.faults {
            // Every run gives its stalls, then its kills; in another order its summary
            // would list them otherwise than the replay's.
            return Err(bad(
                "faults",
                "the stalls must come before the kills (a run lists them so)".into(),
            ));
        }
        Ok(spec)
    }

    /// The settings to replay it with ([`LoggedRun::spec`], then [`RunSpec::config`]'s rules
    /// in the log's words: its keys are the Python package's).
    ///
    /// # Errors
    /// [`ReplayError::Invalid`], one line starting with `origin`.
    pub fn config(&self, origin: &str) -> Result<RunConfig, ReplayError> {
        (self.spec(origin)?.config(Speech::Keywords))
            .map_err(|e| ReplayError::Invalid(format!("{origin}: {e}")))
    }
}

/// A session's command log: every run, in order.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionLog {
    /// Format version: 1 to 3 (`SESSION_VERSION`).
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
    /// A value a run's settings refuse ([`RunSpec::config`]), an unknown version, or a run
    /// that cannot start (its brain or graph not loaded): one line.
    #[error("{0}")]
    Invalid(String),
    /// Real-clock runs are not reproducible.
    #[error("run {0} used the real clock, which cannot be replayed exactly")]
    RealClock(usize),
    /// A run switched to the real clock part way (the lab's `c`): its real-clock part is
    /// not reproducible.
    #[error("run {run} went under the real clock at t={at_s:.3} s (the lab's c), which cannot be replayed exactly")]
    SwitchedClock {
        /// The run, from 1.
        run: usize,
        /// When it first switched, run time, s.
        at_s: f64,
    },
}

impl SessionLog {
    /// An empty log of the current version.
    pub fn new() -> Self {
        SessionLog {
            version: SESSION_VERSION,
            runs: Vec::new(),
        }
    }

    /// Read a session log (JSON) and check every run as the command line checks the same
    /// values: refused when not a regular file, larger than `MAX_SESSION_BYTES`, of an
    /// unknown version, or holding any value a flag would refuse.
    ///
    /// # Errors
    /// [`ReplayError`] naming the file, and the run and field at fault.
    pub fn load(path: &Path) -> Result<Self, ReplayError> {
        let shown = path.display().to_string();
        let bytes = ratelab_core::input::read_regular_file(path, MAX_SESSION_BYTES)
            .map_err(|e| ReplayError::Read(e.to_string()))?;
        let text = ratelab_core::input::utf8_text(bytes).map_err(|e| ReplayError::Parse {
            path: shown.clone(),
            detail: e.to_string(),
        })?;
        let mut log: SessionLog = serde_json::from_str(&text).map_err(|e| ReplayError::Parse {
            path: shown.clone(),
            detail: e.to_string(),
        })?;
        if !(1..=SESSION_VERSION).contains(&log.version) {
            return Err(ReplayError::Invalid(format!(
                "{shown}: version {} is not one this ratelab reads (1..={SESSION_VERSION})",
                log.version
            )));
        }
        if log.runs.len() > MAX_LOGGED
            || log
                .runs
                .iter()
                .any(|r| r.commands.len() > MAX_LOGGED || r.clock_switches_ns.len() > MAX_LOGGED)
        {
            return Err(ReplayError::Invalid(format!(
                "{shown}: more than {MAX_LOGGED} runs, commands or clock switches"
            )));
        }
        for r in &mut log.runs {
            r.faults_as_given = log.version < 3;
        }
        for (i, r) in log.runs.iter().enumerate() {
            r.config(&format!("{shown}: run {}", i + 1))?;
        }
        Ok(log)
    }

    /// Write it (pretty JSON) through [`ratelab_core::output`]: a temporary file beside `path`,
    /// moved into place; never through a symbolic link or into a non-regular file. The
    /// session rewrites its own log after every run and command, so an existing regular
    /// file is replaced: whoever starts a session checks the name once first
    /// ([`ratelab_core::output::check_target`], honouring `--force`).
    ///
    /// # Errors
    /// [`ratelab_core::output::OutputError`] naming the file.
    pub fn save(&self, path: &Path) -> Result<(), ratelab_core::output::OutputError> {
        let text = serde_json::to_string_pretty(self).expect("serializable") + "\n";
        ratelab_core::output::write_file(path, true, text.as_bytes())
    }

    /// Whether `replayed` (run `index` replayed) matches the live run's metrics byte for byte,
    /// as `metrics.json` would print them; `None` when the live run logged none. A version-1
    /// log predates the `graph`/`nodes`/`topics` keys, so those are left out of its comparison.
    pub fn matches(&self, index: usize, replayed: &Metrics) -> Option<bool> {
        let mut live = serde_json::to_value(self.runs.get(index)?.metrics.as_ref()?).ok()?;
        let mut replayed = serde_json::to_value(replayed).ok()?;
        if self.version < 2 {
            for m in [&mut live, &mut replayed] {
                if let Some(m) = m.as_object_mut() {
                    for key in ["graph", "nodes", "topics"] {
                        m.remove(key);
                    }
                }
            }
        }
        Some(
            serde_json::to_string_pretty(&live).ok()?
                == serde_json::to_string_pretty(&replayed).ok()?,
        )
    }
}

/// Re-run logged run `index` headless under the virtual clock, as any run starts
/// ([`LoggedRun::spec`], [`RunSpec::start`]): its brain loaded, nothing written.
///
/// # Errors
/// [`ReplayError`]; real-clock runs are refused, and a run that ended before its first
/// instant (nothing to replay).
pub fn replay_run(log: &SessionLog, index: usize) -> Result<Metrics, ReplayError> {
    let r = &log.runs[index];
    if r.clock != ClockKind::Virtual {
        return Err(ReplayError::RealClock(index + 1));
    }
    if let Some(&at) = r.clock_switches_ns.first() {
        return Err(ReplayError::SwitchedClock {
            run: index + 1,
            at_s: Nanos(at).as_secs_f64(),
        });
    }
    if r.end_ns == 0 {
        return Err(ReplayError::Invalid(format!(
            "run {} ended before its first instant: nothing to replay",
            index + 1
        )));
    }
    let origin = format!("run {}", index + 1);
    let said = |e: anyhow::Error| ReplayError::Invalid(format!("{origin}: {e}"));
    let opts = StartOptions {
        speech: Speech::Keywords,
        echo: false,
        ..StartOptions::command_line(StopFlag::new())
    };
    let run = r.spec(&origin)?.start(opts).map_err(said)?;
    Ok(run.wait().map_err(said)?.report.metrics)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn commands_after_the_last_instant_are_told_apart() {
        let mut run = LoggedRun::starting(&RunConfig::default(), "scripted");
        for at_ns in [100, 200, 300] {
            run.commands.push(TimedCommand {
                at_ns,
                command: Command::SetQueueDepth { depth: 2 },
            });
        }
        run.end_ns = 200;
        let at = |c: &[TimedCommand]| c.iter().map(|c| c.at_ns).collect::<Vec<_>>();
        assert_eq!(
            at(run.applied()),
            [100, 200],
            "at the end: before its instant ran"
        );
        assert_eq!(at(run.after_end()), [300]);
        run.end_ns = 300;
        assert!(run.after_end().is_empty());
    }

    #[test]
    fn a_logged_run_s_spec_gives_back_its_exact_times_graph_faults_and_commands() {
        let mut cfg = RunConfig {
            clock: ClockKind::Virtual,
            seed: 7,
            phase_offsets: vec![Nanos(1), Nanos(999_999_999), Nanos(123_456_789)],
            faults: vec![
                ratelab_core::qos::Fault {
                    node: "policy".into(),
                    at: Nanos(1_000_000_001),
                    duration: Some(Nanos(3)),
                },
                ratelab_core::qos::Fault {
                    node: "sensor".into(),
                    at: Nanos(2_000_000_003),
                    duration: None,
                },
            ],
            ..RunConfig::default()
        };
        cfg.set_control_hz(33.0).unwrap();
        let mut run = LoggedRun::starting(&cfg, "scripted");
        run.commands = vec![
            TimedCommand {
                at_ns: 500_000_001,
                command: Command::SetQueueDepth { depth: 2 },
            },
            TimedCommand {
                at_ns: 9_000_000_000,
                command: Command::SetSensorHz { hz: 40.0 },
            },
        ];
        // Every end a run can have, the longest too, comes back to the ns.
        for end_ns in [
            1,
            999_999_999,
            1_234_567_891,
            (1 << 53) + 1,
            MAX_DURATION.0 - 1,
        ] {
            run.end_ns = end_ns;
            let spec = run.spec("run 1").unwrap();
            let back = spec.config(Speech::Keywords).unwrap();
            assert_eq!(back.duration, Nanos(end_ns));
            assert_eq!(back.phase_offsets, cfg.phase_offsets);
            assert_eq!(back.faults, cfg.faults);
            assert_eq!(back.graph, cfg.graph);
            assert_eq!((back.seed, back.clock), (7, ClockKind::Virtual));
            let (during, after) = spec.commands_at(back.duration);
            let split = (run.applied(), run.after_end());
            assert_eq!(during, split.0);
            assert_eq!(after, split.1);
        }
        // A kill listed before a stall: the replay's summary would list them otherwise.
        run.faults.reverse();
        let err = run.spec("run 1").unwrap_err().to_string();
        assert_eq!(
            err,
            "run 1: faults: the stalls must come before the kills (a run lists them so)"
        );
        run.faults.reverse();
        // A kill from past the longest run (MAX_DURATION, 10 years) could never take effect;
        // a stall longer than it is refused as `--stall` refuses it. At the bound: accepted.
        let max = MAX_DURATION.0;
        let checked = |run: &LoggedRun| match run.spec("run 1") {
            Err(e) => Err(e.to_string()),
            Ok(s) => s
                .config(Speech::Keywords)
                .map(|_| ())
                .map_err(|e| e.to_string()),
        };
        for (kill_at, stall_ns, ok) in [
            (max, max, true),
            (max + 1, 3, false),
            (10_000_000_000_000_000_000, 3, false),
            (2_000_000_003, max + 1, false),
        ] {
            run.faults[1].at = Nanos(kill_at);
            run.faults[0].duration = Some(Nanos(stall_ns));
            match checked(&run) {
                Ok(()) => assert!(ok, "{kill_at} {stall_ns}: accepted"),
                Err(e) => {
                    assert!(!ok, "{kill_at} {stall_ns}: {e}");
                    assert!(e.contains("ratelab::limits::MAX_DURATION_S"), "{e}");
                }
            }
        }
    }

    #[test]
    fn a_logged_run_s_commands_are_checked_by_the_run_s_rules_in_order_and_by_the_graph() {
        let mut run = LoggedRun::starting(&RunConfig::default(), "scripted");
        run.end_ns = 1_000_000_000;
        run.commands = vec![
            TimedCommand {
                at_ns: 200,
                command: Command::SetQueueDepth { depth: 2 },
            },
            TimedCommand {
                at_ns: 100,
                command: Command::SetQueueDepth { depth: 3 },
            },
        ];
        let err = run.config("f: run 1").unwrap_err().to_string();
        assert_eq!(
            err,
            "f: run 1: commands[1]: at_ns 100 is before the previous command's 200"
        );
        run.commands[1].at_ns = 300;
        run.commands[1].command = Command::SetNodeHz {
            node: "planner".into(),
            hz: 5.0,
        };
        let err = run.config("f: run 1").unwrap_err().to_string();
        assert!(err.starts_with("f: run 1: commands[1]: "), "{err}");
        assert!(err.contains("planner"), "{err}");
    }

    #[test]
    fn an_older_log_s_injected_faults_are_booked_as_its_runs_booked_them() {
        let mut run = LoggedRun::starting(&RunConfig::default(), "scripted");
        run.end_ns = 5_000_000_000;
        let stall = Command::InjectFault {
            fault: "policy@1+0.5".into(),
        };
        run.commands = vec![TimedCommand {
            at_ns: 1_200_000_000,
            command: stall.clone(),
        }];
        let now = run.spec("run 1").unwrap();
        assert_eq!(
            now.commands[0].command, stall,
            "this version's: from its instant"
        );
        run.faults_as_given = true;
        let older = run.spec("run 1").unwrap();
        assert_eq!(
            older.commands[0].command,
            Command::InjectFaultAsGiven {
                fault: "policy@1+0.5".into()
            }
        );
        // Read from a version-2 file, so; from a file of this version, not.
        let dir = tempfile::tempdir().unwrap();
        for (version, as_given) in [(2, true), (SESSION_VERSION, false)] {
            let log = SessionLog {
                version,
                runs: vec![run.clone()],
            };
            let file = dir.path().join(format!("v{version}.json"));
            log.save(&file).unwrap();
            let read = SessionLog::load(&file).unwrap();
            assert_eq!(read.runs[0].faults_as_given, as_given, "version {version}");
        }
    }
}
