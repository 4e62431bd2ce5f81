//! A live run's messages with its front end: [`Control`] in, [`Telemetry`] out, and the
//! virtual clock's [`Speed`] ladder. The lab's engine (`ratelab::session`) speaks it with
//! the terminal, and a watcher of a graph across processes (`ratelab::distributed::monitor`)
//! tells what it sees in it; both layers sit above this one, neither above the other.

use crate::command::{parse_fault, Command};
use crate::config::RunConfig;
use crate::scheduler::EndReason;
use ratelab_core::metrics::Metrics;
use ratelab_core::runlog::StepRecord;
use ratelab_core::time::Nanos;
use std::path::PathBuf;

/// "Run until stopped": the duration of an open-ended lab run, the longest any run may be
/// ([`ratelab_core::time::MAX_DURATION`]), so that its session log replays.
pub const UNBOUNDED: Nanos = ratelab_core::time::MAX_DURATION;

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
    /// Stall `node` for `duration` from the next instant the run takes up (the lab's `k`):
    /// applied, told and booked as the [`Command::InjectFault`] it becomes there
    /// ([`crate::command::stall_from`]), so a session log replays it as it ran. Where the
    /// front end's clock trails the run's (the lab at ×8 or at max speed draws what has
    /// already run), a stall from the front end's time could be over before the run takes
    /// it up.
    Stall {
        /// The node's name.
        node: String,
        /// How long its ticks are swallowed.
        duration: Nanos,
    },
    /// Pause or resume.
    TogglePause,
    /// While paused (virtual clock): run until the next actuator tick.
    Step,
    /// While paused (virtual clock): put the run at this run time ([`crate::runcore::RunCore::seek`]):
    /// forward it runs there; back it is as it was then, and what runs from there is a new
    /// branch of the run.
    Seek(Nanos),
    /// Start a new run with the current settings: same seed, or the next one.
    Reset {
        /// Use `seed + 1`.
        next_seed: bool,
    },
    /// Go on under the other clock: the running graph changes clocks in place (its state
    /// carries across, [`Telemetry::ClockSwitched`]); a run that has ended, or one offered to
    /// ROS 2 (its bridge serves one clock), restarts under the other clock instead.
    SwitchClock,
    /// Virtual pacing.
    SetSpeed(Speed),
    /// A file the run's code comes from was saved (the graph file, a Python node's script, a
    /// Python brain): run the graph again from t = 0 with what the files hold now, when it
    /// loads; else keep the run going and say why ([`Telemetry::Reloaded`]).
    Reload {
        /// The file saved.
        file: std::path::PathBuf,
    },
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
    Step(Box<StepRecord>),
    /// The run was put back at this run time ([`Control::Seek`]): the front end shows it as it
    /// was then (what it was told up to then), and what comes next is a new branch.
    Rewound {
        /// The run time it is at.
        at: Nanos,
    },
    /// One node tick under the real clock: node index (tie-break rank), run time,
    /// lateness and how long it took.
    NodeTick {
        /// Node index ([`crate::graph::NodeId`]).
        node: usize,
        /// Run time.
        now: Nanos,
        /// Actual − scheduled.
        lateness: Nanos,
        /// Wall time from its start to its end ([`crate::scheduler::TickReport::took`]).
        took: Nanos,
    },
    /// Periodic status.
    Status {
        /// Run time now (virtual: the last instant run).
        now: Nanos,
        /// Paused?
        paused: bool,
        /// Virtual pacing.
        speed: Speed,
        /// Each node's set rate, Hz, by node index.
        rates: Vec<f64>,
        /// Each topic's depth, by topic index.
        depths: Vec<usize>,
        /// Each topic's QoS, by topic index (as [`Telemetry::Status::depths`]: while
        /// frozen, the next run's).
        qos: Vec<ratelab_core::qos::TopicQos>,
        /// Each node's liveliness now, by node index: `None` without a lease.
        alive: Vec<Option<bool>>,
        /// The brain's label.
        policy: String,
        /// Virtual clock, when the graph has executors or compute times
        /// ([`ratelab_core::executor`]): each node's ticks and skipped ticks so far, by node index.
        exec: Option<Vec<(u64, u64)>>,
        /// Every topic's counters at `now`, as a step record carries them: they keep the
        /// lab's counts current while the actuator sends no step (stalled, killed).
        /// `None` where the sender has none (a lab attached to a launch).
        topics: Option<Box<ratelab_core::runlog::TopicCounters>>,
    },
    /// Virtual clock with executors or compute times: the ticks that ended since the last
    /// such message, oldest first ([`ratelab_core::executor::CallbackSpan`]; the lab's executor
    /// timeline). Under the real clock [`Telemetry::NodeTick`] gives the same.
    Callbacks(Vec<ratelab_core::executor::CallbackSpan>),
    /// A notice for the front end's log line (a change set for the next run, a refused
    /// real-time priority).
    Applied(String),
    /// A change of rate, depth or brain took effect in the running graph at run time `at`
    /// (virtual: the instant before which it was applied; real: when the engine applied
    /// it). It starts a new segment of the run: the front end's totals since the last
    /// change restart there.
    Changed {
        /// Run time the change took effect.
        at: Nanos,
        /// The change in words ([`describe`]).
        text: String,
    },
    /// A fault was injected while the run goes ([`Command::InjectFault`]: the lab's `k`, a
    /// session log's `inject_fault`), told just before its [`Telemetry::Changed`], as it
    /// takes effect: from the instant the command was applied before when it was given an
    /// earlier time. The front end marks its node while it lasts, as it marks one given at
    /// the start.
    Faulted(ratelab_core::qos::Fault),
    /// The engine has taken a [`Control::Seek`] (whether it moved the run or not: past the
    /// end, or not paused): the run is at `at`. A front end that sends seeks faster than
    /// they are answered counts these to know when its cursor is the engine's again.
    Sought {
        /// Run time the run is at after the seek.
        at: Nanos,
    },
    /// The running graph changed clocks in place at run time `at` ([`Control::SwitchClock`]
    /// on a run that has not ended; `ratelab::runcore::RunCore::run_real`): the same run
    /// goes on under `clock`, its nodes, topics, counters and plant as they were. Like
    /// [`Telemetry::Changed`] it starts a new segment of the run.
    ClockSwitched {
        /// Run time the other clock took over.
        at: Nanos,
        /// The clock the run goes on under.
        clock: crate::config::ClockKind,
    },
    /// The run ended (fall, duration, node failure); the state is frozen until reset or quit.
    Ended {
        /// Its summary.
        metrics: Box<Metrics>,
        /// How it ended.
        reason: EndReason,
    },
    /// Something went wrong that the user should read (one line).
    Error(String),
    /// The run could not start, and why (one line): its brain, its recording, its graph (a
    /// node's script that fails to load) or its ROS 2 link. No `Started` came; the engine
    /// waits for a save, a reset or a switch of clocks. The front end shows that no run is
    /// going rather than the run before's verdict.
    NotStarted(String),
    /// The [`Telemetry::Error`] line said last, again with a new count (a call that still
    /// has not returned: `… after 3 s …`): the front end shows it in place of that line
    /// only while that line is what it shows (it does not cover a newer message), and does
    /// not log it again.
    Recount(String),
    /// A saved file was taken up ([`Control::Reload`]): the run that follows (its
    /// `Started` comes next) runs the new code, and the front end keeps the run before as a
    /// ghost beside it. `line` begins `reloaded FILE:` and says what changed.
    Reloaded {
        /// The line to show.
        line: String,
    },
    /// A graph across processes (a watcher, `ratelab::distributed::monitor`): the
    /// over-the-wire latency so far of each topic that crosses a process boundary, as
    /// (topic index, p50 µs, p99 µs), from its publisher's send to its subscriber's delivery.
    Wire(Vec<(usize, f64, f64)>),
}

impl Telemetry {
    /// About how many bytes the message holds, itself and what it points to: what a front
    /// end that keeps messages (the lab's journal, for seeking back) counts against its
    /// budget. A large graph's step and status carry every topic's counters, so their size
    /// grows with the graph.
    pub fn approx_bytes(&self) -> usize {
        use std::mem::size_of;
        // Counted whole, though consecutive steps share the blocks of topics that did not
        // change: an upper bound.
        let spilled = |c: &ratelab_core::runlog::TopicCounters| c.heap_bytes();
        size_of::<Telemetry>()
            + match self {
                Telemetry::Step(s) => size_of::<StepRecord>() + spilled(&s.topics),
                Telemetry::Status {
                    rates,
                    depths,
                    qos,
                    alive,
                    policy,
                    exec,
                    topics,
                    ..
                } => {
                    rates.len() * size_of::<f64>()
                        + depths.len() * size_of::<usize>()
                        + qos.len() * size_of::<ratelab_core::qos::TopicQos>()
                        + alive.len() * size_of::<Option<bool>>()
                        + policy.len()
                        + exec.as_ref().map_or(0, |e| e.len() * 16)
                        + topics.as_deref().map_or(0, |c| {
                            size_of::<ratelab_core::runlog::TopicCounters>() + spilled(c)
                        })
                }
                Telemetry::Callbacks(spans) => {
                    spans.len() * size_of::<ratelab_core::executor::CallbackSpan>()
                }
                Telemetry::Applied(text) | Telemetry::Error(text) | Telemetry::NotStarted(text) => {
                    text.len()
                }
                Telemetry::Changed { text, .. } => text.len(),
                Telemetry::Reloaded { line } => line.len(),
                Telemetry::Wire(w) => w.len() * 24,
                // Once a run, or small.
                _ => 4096,
            }
    }
}

/// A command in words, for logs.
pub fn describe(cmd: &Command) -> String {
    match cmd {
        Command::SetControlHz { hz } => format!("control rate → {hz} Hz"),
        Command::SetSensorHz { hz } => format!("sensor rate → {hz} Hz"),
        Command::SetQueueDepth { depth } => format!("queue depth → {depth}"),
        Command::SetNodeHz { node, hz } => format!("{node} rate → {hz} Hz"),
        Command::SetTopicDepth { topic, depth } => format!("{topic} depth → {depth}"),
        Command::SetTopicQos { topic, pairs } => format!("{topic} QoS → {pairs}"),
        Command::SetPolicy { spec } => format!("brain → {spec}"),
        Command::SetExecutor { executor } => format!("executor → {executor}"),
        Command::SetPhase { node, phase_ms } => {
            format!("phase {} → {phase_ms} ms", shown(node))
        }
        Command::InjectFault { fault } | Command::InjectFaultAsGiven { fault } => {
            match parse_fault(fault) {
                Ok(f) => format!("fault → {}", shown(&f.to_string())),
                Err(_) => format!("fault → {}", shown(fault)),
            }
        }
    }
}

/// Text from a command (a session log is untrusted) as a status line shows it: printable,
/// at most 64 characters.
fn shown(text: &str) -> String {
    ratelab_core::text::printable(text)
        .chars()
        .take(64)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratelab_core::topic::TopicStats;

    fn step(topics: usize) -> Telemetry {
        Telemetry::Step(Box::new(StepRecord {
            step: 1,
            t: Nanos::ZERO,
            pole_angle: 0.0,
            pole_angvel: 0.0,
            cart_pos: 0.0,
            action: 0.0,
            latency: None,
            held_stamp: None,
            nonfinite: false,
            topics: (0..topics).map(|_| TopicStats::default()).collect(),
            published: None,
            fell: false,
            estimate: None,
        }))
    }

    #[test]
    fn a_large_graph_s_step_counts_every_topic_s_counters() {
        let small = step(3).approx_bytes();
        let large = step(1000).approx_bytes();
        assert!(small < 4096, "{small}");
        assert!(large >= 1000 * std::mem::size_of::<TopicStats>(), "{large}");
        assert_eq!(step(7).approx_bytes(), small, "inline up to 7 topics");
    }
}
