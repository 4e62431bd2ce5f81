//! The run core: one graph in this process — its nodes, topics, executors, scheduler and
//! plant — advanced under the virtual clock instant by instant or event by event, run
//! under the real clock, changed by commands, and **captured** and **restored** whole, so that restoring what was captured at t and running
//! on gives, byte for byte, the run's own continuation.
//!
//! Every run of a graph goes through it; its drivers are thin:
//! - under the virtual clock, through one loop, [`drive::drive`], under a policy that
//!   supplies the pace, the commands and the event source:
//!   - instant by instant ([`RunCore::step`]'s instants): `ratelab::run::run` (and so the
//!     headless run, `sweep`, `cliff`, the exercises, `bench` and `replay`), the lab's
//!     trial judge and the lab's engine, which paces it against the wall clock
//!     (`ratelab::session`);
//!   - event by event ([`RunCore::next_event`], [`RunCore::run_event`],
//!     [`RunCore::ran_elsewhere`]): each process of a launch, which runs its own nodes'
//!     events and takes the others' from their reports (`ratelab::distributed`); the
//!     launcher follows the same order without ticks ([`Follower`]);
//! - under the real clock ([`RunCore::run_real`]): the headless run, the lab's engine and
//!   each process of a launch hand the core's graph to the real-clock executor's threads
//!   ([`crate::scheduler::run_real`]) and take it back at the end; the lab's engine and a
//!   launch's process through [`drive::watch_real`], which takes their controls on the
//!   calling thread meanwhile.
//!
//! # A clock switch in place
//! One run may change clocks as it goes (the lab's `c`): [`RunCore::run_real`] from the
//! instant the virtual clock reached starts each node at its next tick there, with the real
//! clock reading that instant; when the real clock is stopped the virtual one takes the
//! graph back at the time it stopped, each node's next tick on the grid it ran on. State
//! carries across both ways (nodes, topics, counters, the plant, the run log); the real
//! clock's part is not reproducible, so a capture that replays cannot give a run that went
//! under it.
//!
//! # What an instant is
//! [`RunCore::step`] runs the next instant of the scheduler ([`VirtualScheduler::run_instant`]:
//! the executors' rules, the chapter's tie-break order), after applying the commands
//! scheduled at or before it ([`TimedCommand`]: a command takes effect just before the first
//! instant at or after its time, as `replay` of a session log applies it) and the executor
//! plan a command asked for. A run ends when the next instant is past its duration (at the
//! duration), a node stops the graph (the pole fell), or a node fails.
//!
//! # Capture and restore
//! [`RunCore::capture`] takes the run's complete state between two instants:
//! - the plant's (MuJoCo's integration state, `mj_getState`, and its step count);
//! - every node's ([`GraphNode::save`]: held forces, filters, noise and compute-time
//!   generators, publishes held by a tick still computing);
//! - every topic's, each subscription's queue (messages buffered and on the link, depth,
//!   QoS, the link's generator, counters, deadline timers);
//! - each node's rate and liveliness, the faults injected by command, the brain in the slot
//!   ([`Policy::duplicate`]), the executors asked for, the scheduler (timers, running
//!   ticks, counters, its plan);
//! - the run log (step count, exact latency samples, the trace when kept, fall, watchdog),
//!   the commands applied and those still to come.
//!
//! When some part cannot be captured — a Python node's or brain's objects, a ROS 2 node's
//! proxy, a program's own kind that does not implement [`ratelab_core::ports::RustNode::save`] —
//! the capture is a *replay*: the commands applied up to then. Restoring it builds the graph
//! again from its settings (with the brain [`CoreOptions::remake_brain`] makes) and runs it
//! from 0 to the captured instant under the virtual clock, which is deterministic: the same
//! state, reached the long way. Such a restore gives a new graph: its step observers are made
//! again ([`CoreOptions::remake_observers`]); what else was attached to the old one (topic
//! taps, a ROS 2 offer) is not carried over.
//!
//! A restore's cost: copies of the parts above (the trace and the latency samples grow with
//! the run; BENCHMARKS.md gives the chapter's graph's figures), or, for a replay, the run up
//! to the instant.

use crate::command::{Command, TimedCommand};
use crate::config::RunConfig;
use crate::graph::nodes::GraphNode;
use crate::graph::{lock, Graph, GraphHandles, StepObserver};
use crate::plant::PlantState;
use crate::plant::{CartPole, PlantError};
use crate::policy::{BrainSlot, Policy};
use crate::scheduler::{EndReason, Event, InstantOutcome, RunEnd, StopFlag, VirtualScheduler};
use ratelab_core::executor::{ExecutionPlan, ExecutorOverride};
use ratelab_core::msg::TopicSnapshot;
use ratelab_core::node::Flow;
use ratelab_core::node::NodeState;
use ratelab_core::qos::LivelinessState;
use ratelab_core::runlog::RunLog;
use ratelab_core::time::Nanos;

mod capture;
pub mod drive;
mod follower;
mod real;
mod restart;
pub use capture::{Capture, RestoreError};
pub use follower::Follower;
pub use real::RealEnd;

/// A run that could not start.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Bad settings.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The plant could not be built.
    #[error(transparent)]
    Plant(#[from] PlantError),
    /// The graph could not be built.
    #[error(transparent)]
    Graph(#[from] crate::graph::GraphError),
}

/// Build the plant (reset to `cfg.seed`) and the graph for `cfg`.
///
/// # Errors
/// [`RunError`] for bad settings or a plant that will not load.
pub fn build_graph(
    cfg: &RunConfig,
    brain: BrainSlot,
    keep_trace: bool,
    observers: Vec<Box<dyn StepObserver>>,
) -> Result<Graph, RunError> {
    cfg.validate()?;
    build_validated_graph(cfg, brain, keep_trace, observers)
}

/// [`build_graph`] for a `cfg` its caller has validated ([`RunConfig::validate`], as
/// `ratelab_drivers::run_spec::RunSpec::config` does last): the plant (reset to `cfg.seed`)
/// and the graph, without checking `cfg` again. Given a `cfg` that was not validated, the
/// graph may be built from settings [`build_graph`] refuses.
///
/// # Errors
/// [`RunError`] for a plant that will not load or a graph that cannot be built.
pub fn build_validated_graph(
    cfg: &RunConfig,
    brain: BrainSlot,
    keep_trace: bool,
    observers: Vec<Box<dyn StepObserver>>,
) -> Result<Graph, RunError> {
    let mut plant = CartPole::new()?;
    plant.reset(cfg.seed);
    Ok(Graph::build(
        &cfg.graph,
        plant,
        brain,
        cfg.seed,
        keep_trace,
        observers,
        &cfg.faults,
    )?)
}

/// The virtual-clock executor for `cfg`'s graph: its phase offsets and execution plan
/// (executors, callback groups); response times are measured when the graph has executors
/// or compute times.
pub fn virtual_scheduler(cfg: &RunConfig, nodes: &[GraphNode]) -> VirtualScheduler {
    VirtualScheduler::with_plan(
        nodes,
        &cfg.first_deadlines(),
        cfg.graph.execution_plan(),
        cfg.graph.has_executors_or_compute(),
    )
}

/// A number for each graph a run core builds in this process.
fn next_graph_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// Makes the run's brain afresh, for a restore that replays ([`RunCore::restore`]).
pub type BrainFactory = Box<dyn Fn() -> Result<Box<dyn Policy>, String> + Send>;

/// Makes the step observers afresh for the graph a restore that replays builds.
pub type ObserverFactory = Box<dyn Fn() -> Vec<Box<dyn StepObserver>> + Send>;

/// How a [`RunCore`] is built.
#[derive(Default)]
pub struct CoreOptions {
    /// Keep every step record (`trace.csv`); a capture then copies the trace.
    pub keep_trace: bool,
    /// Told about every actuator tick.
    pub observers: Vec<Box<dyn StepObserver>>,
    /// Commands to apply at run times (any order: they are sorted by `at_ns`, stably).
    pub commands: Vec<TimedCommand>,
    /// Told about every tick as its executor ran it, when executors or compute times apply.
    pub on_span: Option<ratelab_core::executor::SpanHook>,
    /// Makes the brain again for a restore that replays; without it such a restore fails
    /// with [`RestoreError::CannotReplay`].
    pub remake_brain: Option<BrainFactory>,
    /// Makes the step observers again for the graph a restore that replays builds (without
    /// it that graph has none).
    pub remake_observers: Option<ObserverFactory>,
    /// Keep a capture this often (run time) for [`RunCore::seek`] (the lab's time travel;
    /// [`HISTORY_EVERY`]); `None`: keep none, and seeking back fails.
    pub history_every: Option<Nanos>,
}

/// How often (run time) the lab keeps a capture to seek back to.
pub const HISTORY_EVERY: Nanos = Nanos(Nanos::SECOND.0);

/// The most captures a run core keeps for seeking. Past it every other one goes and the
/// spacing doubles, so a long run's history costs bounded memory, and reaching any instant
/// costs at most one spacing of run time after the restore. A large graph keeps fewer
/// ([`max_history`]).
pub const MAX_HISTORY: usize = 128;

/// The fewest captures a run core keeps for seeking, however large its graph.
pub const MIN_HISTORY: usize = 4;

/// What the captures kept for seeking may take together, bytes (estimated: about
/// [`CAPTURE_BYTES_PER_PART`] per node and topic; measured 7.5 KB on a generated 1,000-node
/// graph, BENCHMARKS.md).
pub const HISTORY_BYTES: usize = 256 << 20;

/// A capture's estimated bytes per node and per topic (their queues, counters and
/// statistics).
pub const CAPTURE_BYTES_PER_PART: usize = 8 << 10;

/// How many captures a run core of `nodes` nodes and `topics` topics keeps for seeking:
/// [`HISTORY_BYTES`] over a capture's estimated size, within [`MIN_HISTORY`] and
/// [`MAX_HISTORY`] (the chapter's graph keeps 128; a 1,000-node one 16).
pub fn max_history(nodes: usize, topics: usize) -> usize {
    let capture = CAPTURE_BYTES_PER_PART.saturating_mul(nodes + topics).max(1);
    (HISTORY_BYTES / capture).clamp(MIN_HISTORY, MAX_HISTORY)
}

/// What [`RunCore::step`] did.
#[derive(Clone, Debug, PartialEq)]
pub enum Step {
    /// An instant ran at `at`; `ticked` has bit `i % 64` set for each node `i` that ticked.
    Ran {
        /// The instant's run time.
        at: Nanos,
        /// The nodes that ticked, as bits.
        ticked: u64,
    },
    /// The run has ended (now or earlier), as given.
    Ended(RunEnd),
}

/// One graph in this process, under either clock (module docs).
pub struct RunCore {
    /// This graph's number in the process (a new one for each graph built).
    graph_id: u64,
    cfg: RunConfig,
    nodes: Vec<GraphNode>,
    handles: GraphHandles,
    sched: VirtualScheduler,
    /// Commands given in advance, sorted by `at_ns`.
    scheduled: Vec<TimedCommand>,
    next_scheduled: usize,
    /// Every command applied, scheduled or not, at the instant before which it took effect.
    applied: Vec<TimedCommand>,
    /// The commands applied by hand ([`RunCore::apply`]), which a seek back applies again.
    by_hand: Vec<TimedCommand>,
    /// Captures kept to seek back to, oldest first ([`RunCore::seek`]).
    history: Vec<Capture>,
    /// Their spacing (`None`: none kept), and when the next is due.
    history_every: Option<Nanos>,
    next_history: Nanos,
    /// The most captures kept ([`max_history`]).
    max_history: usize,
    end: Option<RunEnd>,
    /// The parts of the run that cannot run again, `(from, to)` run times, oldest first:
    /// those the real clock ran and gave back ([`RunCore::run_real`]), and the instants nodes
    /// were restarted in place (`from == to`, [`RunCore::restart_nodes`]). Neither a replay
    /// from t = 0 nor a seek can run them again.
    real_parts: Vec<(Nanos, Nanos)>,
    keep_trace: bool,
    on_span: Option<ratelab_core::executor::SpanHook>,
    remake_brain: Option<BrainFactory>,
    remake_observers: Option<ObserverFactory>,
}

impl RunCore {
    /// Build `cfg`'s graph (the plant reset to `cfg.seed`) with `brain` in its slot, at
    /// t = 0 with nothing run. `cfg.clock` is not read: the driver picks the clock
    /// ([`RunCore::step`] and [`RunCore::next_event`] the virtual one, [`RunCore::run_real`]
    /// the real one).
    ///
    /// # Errors
    /// [`RunError`] for bad settings, a plant that will not load or a graph that cannot be
    /// built.
    pub fn new(
        cfg: &RunConfig,
        brain: Box<dyn Policy>,
        opts: CoreOptions,
    ) -> Result<Self, RunError> {
        let mut opts = opts;
        let observers = std::mem::take(&mut opts.observers);
        let graph = build_graph(cfg, BrainSlot::new(brain), opts.keep_trace, observers)?;
        Ok(Self::with_graph(cfg, graph, opts))
    }

    /// A run core for `graph`, built for `cfg` by [`build_graph`] (with its observers, and
    /// keeping the trace or not as it was built: `opts.observers` and `opts.keep_trace` are
    /// not read), at t = 0 with nothing run.
    pub fn with_graph(cfg: &RunConfig, graph: Graph, opts: CoreOptions) -> Self {
        let Graph { nodes, handles } = graph;
        let keep_trace = lock(&handles.log).keep_trace;
        let mut sched = virtual_scheduler(cfg, &nodes);
        if let Some(h) = &opts.on_span {
            sched.set_span_hook(h.clone());
        }
        sched.take_plans_from(handles.plan_request.clone());
        let mut scheduled = opts.commands;
        scheduled.sort_by_key(|c| c.at_ns);
        let mut core = RunCore {
            graph_id: next_graph_id(),
            cfg: cfg.clone(),
            nodes,
            handles,
            sched,
            scheduled,
            next_scheduled: 0,
            applied: Vec::new(),
            by_hand: Vec::new(),
            history: Vec::new(),
            history_every: opts.history_every.filter(|e| e.0 > 0),
            next_history: Nanos::ZERO,
            max_history: max_history(cfg.graph.nodes.len(), cfg.graph.topics.len()),
            end: None,
            real_parts: Vec::new(),
            keep_trace,
            on_span: opts.on_span,
            remake_brain: opts.remake_brain,
            remake_observers: opts.remake_observers,
        };
        core.keep_history();
        core
    }

    /// The run's settings.
    pub fn config(&self) -> &RunConfig {
        &self.cfg
    }

    /// The graph's handles (topics, rates, plant, log, brain). Do not keep clones across a
    /// [`RunCore::restore`] that replays: it builds a new graph.
    pub fn handles(&self) -> &GraphHandles {
        &self.handles
    }

    /// The scheduler (tick counts, the executors' figures, the next due times).
    pub fn scheduler(&self) -> &VirtualScheduler {
        &self.sched
    }

    /// The scheduler, to take its callback spans.
    pub fn scheduler_mut(&mut self) -> &mut VirtualScheduler {
        &mut self.sched
    }

    /// The newest instant that ran (0 before any).
    pub fn now(&self) -> Nanos {
        self.sched.now()
    }

    /// The next instant [`RunCore::step`] would run; `None` once the run has ended or its
    /// next instant is past its duration.
    pub fn next_instant(&self) -> Option<Nanos> {
        if self.end.is_some() {
            return None;
        }
        self.sched.next_due().filter(|&t| t <= self.cfg.duration)
    }

    /// How the run ended, once it has.
    pub fn end(&self) -> Option<&RunEnd> {
        self.end.as_ref()
    }

    /// The commands applied so far, each at the instant before which it took effect: what
    /// `replay` applies to give this run again.
    pub fn applied(&self) -> &[TimedCommand] {
        &self.applied
    }

    /// Run the next instant (module docs), or say how the run ended.
    pub fn step(&mut self) -> Step {
        if let Some(end) = &self.end {
            return Step::Ended(end.clone());
        }
        let Some(due) = self.prepare_instant() else {
            return Step::Ended(self.finish_at_duration());
        };
        self.run_prepared(due)
    }

    /// Run the instant `due` [`RunCore::prepare_instant`] made ready.
    fn run_prepared(&mut self, due: Nanos) -> Step {
        let ended = match self.sched.run_instant(&mut self.nodes) {
            InstantOutcome::Ran { ticked } => {
                self.keep_history();
                return Step::Ran { at: due, ticked };
            }
            InstantOutcome::Stopped => RunEnd {
                at: self.sched.now(),
                reason: EndReason::NodeStopped,
            },
            InstantOutcome::Failed(reason) => RunEnd {
                at: self.sched.now(),
                reason,
            },
        };
        self.end = Some(ended.clone());
        Step::Ended(ended)
    }

    /// The run's next event, the clock moved on to it: a node's tick starting, or a tick's
    /// held outputs going out after its compute time ([`Event`]), in the order
    /// [`RunCore::step`] runs them. Before an instant's first event the commands scheduled
    /// at or before it are applied, and the executor plan a command asked for is taken, as
    /// [`RunCore::step`] does. `None` once the run has ended or its next instant is past its
    /// duration.
    ///
    /// For a driver that runs an instant's events one at a time: the graph across processes,
    /// where each process runs its own nodes' events and takes the others' from their
    /// reports (`ratelab::distributed::lockstep`). Each event drawn is then either run here
    /// ([`RunCore::run_event`]) or taken as run elsewhere ([`RunCore::ran_elsewhere`]),
    /// before the next is drawn. Captures are taken between instants, not between events.
    pub fn next_event(&mut self) -> Option<Event> {
        if self.end.is_some() {
            return None;
        }
        loop {
            if let Some(e) = self.sched.next_in_instant() {
                return Some(e);
            }
            let due = self.prepare_instant()?;
            self.sched.begin_instant(due);
        }
    }

    /// Run `event` ([`RunCore::next_event`]'s) here: a start ticks its node (its compute
    /// time drawn, its outputs held until it has elapsed); a publish sends the outputs its
    /// tick held. Returns the node's [`Flow`] and the compute time drawn (zero for a
    /// publish). A node that stops the graph or fails ends the run ([`RunCore::end`]).
    ///
    /// # Errors
    /// The node panicked: [`EndReason::NodeFailed`] naming it.
    pub fn run_event(&mut self, event: Event) -> Result<(Flow, Nanos), EndReason> {
        let ran = match event {
            Event::Publish { node, at } => {
                self.nodes[node].publish_held(at);
                Ok((Flow::Continue, Nanos::ZERO))
            }
            Event::Start { node, .. } => self.sched.start_here(&mut self.nodes, node),
        };
        let (_, at) = event.node_at();
        match &ran {
            Ok((Flow::Stop, _)) => self.ended_at(at, EndReason::NodeStopped),
            Err(reason) => self.ended_at(at, reason.clone()),
            Ok(_) => {}
        }
        ran
    }

    /// Take `event` ([`RunCore::next_event`]'s) as run in another process: a start's tick
    /// computed there for `compute` (as that process reports it; zero when it takes no
    /// time), which the executors here account for; a publish changes nothing here (its
    /// messages arrive over the wire).
    pub fn ran_elsewhere(&mut self, event: Event, compute: Nanos) {
        if let Event::Start { node, .. } = event {
            self.sched.start_elsewhere(&self.nodes, node, compute);
        }
    }

    /// End the run at `at` for `reason`, unless it has ended already.
    fn ended_at(&mut self, at: Nanos, reason: EndReason) {
        self.end.get_or_insert(RunEnd { at, reason });
    }

    /// Make ready the next instant: apply the commands scheduled at or before it and take
    /// what they asked of the scheduler. A phase change may move the instant later (the
    /// only node due then now ticks on another grid): the commands up to the new one are
    /// applied first, and so on, so that the instant returned is the one the scheduler runs
    /// next. `None` once the run has ended or its next instant is past its duration.
    fn prepare_instant(&mut self) -> Option<Nanos> {
        loop {
            let due = self.next_instant()?;
            self.apply_scheduled(due);
            self.take_plan();
            if self.sched.next_due() == Some(due) {
                return Some(due);
            }
        }
    }

    /// Apply the commands scheduled at or before `due`, logging each.
    fn apply_scheduled(&mut self, due: Nanos) {
        while let Some(c) = self.scheduled.get(self.next_scheduled) {
            if c.at_ns > due.0 {
                break;
            }
            // Commands were validated when logged; a failure here changes nothing.
            let _ = c.command.apply(&self.handles, Nanos(c.at_ns));
            self.applied.push(c.clone());
            self.next_scheduled += 1;
        }
    }

    /// Run every instant up to and including `t` (or to the run's end).
    pub fn run_until(&mut self, t: Nanos) {
        while self.next_instant().is_some_and(|due| due <= t) && self.step_within(t) {}
    }

    /// Run the next instant if it is at or before `t` once the commands before it are
    /// applied (a phase change may move it past `t`); `true` when one ran.
    fn step_within(&mut self, t: Nanos) -> bool {
        match self.prepare_instant() {
            Some(due) if due <= t => matches!(self.run_prepared(due), Step::Ran { .. }),
            Some(_) => false,
            None => {
                self.finish_at_duration();
                false
            }
        }
    }

    /// Run to the end, checking `stop` before each instant (a stop ends the run as
    /// interrupted at the newest instant run): [`drive::drive`] with nothing paced or taken in
    /// between ([`drive::Unpaced`]).
    pub fn run_to_end(&mut self, stop: &StopFlag) -> RunEnd {
        self.run_to_end_with(&mut drive::Unpaced, stop, None)
    }

    /// Run to the end instant by instant under `policy` ([`drive::drive`] from where the run
    /// stands, `clock` told each instant), checking `stop` before each: how the run ended. A
    /// policy that leaves ([`drive::Intake::Leave`]) ends it as interrupted there.
    pub fn run_to_end_with<P>(
        &mut self,
        policy: &mut P,
        stop: &StopFlag,
        clock: Option<&dyn drive::ClockOut>,
    ) -> RunEnd
    where
        P: drive::DrivePolicy<Nanos, RunCore, Error = std::convert::Infallible> + ?Sized,
    {
        let mut cursor = drive::Cursor::default();
        let Ok(drove) = drive::drive(self, &mut cursor, policy, Some(stop), clock);
        match drove {
            drive::Drove::Ended(end) => end,
            // Instant by instant the run ends (a stop ends it too) unless the policy left.
            _ => self.interrupt(),
        }
    }

    /// End the run now, as interrupted, unless it has ended already; returns how it ended.
    pub fn interrupt(&mut self) -> RunEnd {
        self.end
            .get_or_insert_with(|| RunEnd {
                at: self.sched.now(),
                reason: EndReason::Interrupted,
            })
            .clone()
    }

    /// Apply `command` between instants: it takes effect before the next instant, and is
    /// logged at it ([`RunCore::applied`]); a new executor plan runs from that instant.
    ///
    /// # Errors
    /// A one-line description when the run has ended, or the value breaks the graph's rules
    /// or a brain cannot be loaded ([`Command::apply`]; the run is unchanged).
    pub fn apply(&mut self, command: Command) -> Result<(), String> {
        if self.end.is_some() {
            return Err("the run has ended".into());
        }
        let at = self.sched.next_due().unwrap_or(self.sched.now());
        command.apply(&self.handles, at)?;
        let c = TimedCommand {
            at_ns: at.0,
            command,
        };
        self.applied.push(c.clone());
        self.by_hand.push(c);
        self.take_plan();
        Ok(())
    }

    /// Take what commands asked of the scheduler: an executor plan, phase changes (from the
    /// next instant on).
    /// Apply `command` to a run that has ended, as a lab's user does after its last instant
    /// (paused, before a restart): it sets what the run ended with (its rates, a new
    /// executor plan, which the executors' figures then count in) and runs nothing; not
    /// logged. A replay takes the session's such commands up so ([`Command::apply`], at
    /// the time the session logged: the instant after the run's last, which never ran).
    ///
    /// # Errors
    /// As [`Command::apply`]'s.
    pub fn apply_after_end(&mut self, c: &TimedCommand) -> Result<(), String> {
        c.command.apply(&self.handles, Nanos(c.at_ns))?;
        self.take_plan();
        Ok(())
    }

    fn take_plan(&mut self) {
        let asked = lock(&self.handles.plan_request).take();
        if let Some(plan) = asked {
            self.sched.set_plan(plan);
        }
        let phases = self.handles.phase_request.take();
        if !phases.is_empty() {
            let from = self.sched.next_due().unwrap_or(self.sched.now());
            for (id, phase) in phases {
                let period = self.handles.rate(id).period();
                let start = self.cfg.graph.node(id).start.unwrap_or(Nanos::ZERO);
                self.sched.set_phase(id.0, phase, period, from, start);
            }
        }
    }

    fn finish_at_duration(&mut self) -> RunEnd {
        let end = RunEnd {
            at: self.cfg.duration,
            reason: EndReason::Duration,
        };
        self.end = Some(end.clone());
        end
    }

    /// The run's summary (`metrics.json`) at its end, or now while it runs (as interrupted
    /// now).
    pub fn metrics(&self) -> ratelab_core::metrics::Metrics {
        let end = self.end.clone().unwrap_or(RunEnd {
            at: self.sched.now(),
            reason: EndReason::Interrupted,
        });
        let exec = self.sched.figures(end.at);
        crate::summary::summarize(
            &self.cfg,
            &self.handles,
            &end,
            self.sched.ticks(),
            None,
            exec,
        )
    }

    /// Take the step records kept so far (empty unless [`CoreOptions::keep_trace`]).
    pub fn take_trace(&mut self) -> Vec<ratelab_core::runlog::StepRecord> {
        std::mem::take(&mut lock(&self.handles.log).trace)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_large_graph_keeps_fewer_captures_within_the_bounds() {
        assert_eq!(max_history(3, 2), MAX_HISTORY, "the chapter's graph");
        assert_eq!(max_history(1000, 999), 16);
        assert_eq!(max_history(65_536, 65_536), MIN_HISTORY);
        assert_eq!(max_history(0, 0), MAX_HISTORY);
    }
}
