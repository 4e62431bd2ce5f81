//! A virtual-clock run in the lab: the run core ([`ratelab_runtime::runcore`]) stepped one instant at
//! a time, paced against the wall clock at the chosen speed. Pacing decides only *when* an
//! instant runs, never its order.

use super::compare::RunFigures;
use super::engine::{live_metrics, Engine, Next, Segment};
use crate::run::Command;
use crossbeam_channel::RecvTimeoutError;
use ratelab_core::time::Nanos;
use ratelab_recording::Recording;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::GraphHandles;
use ratelab_runtime::runcore::drive::{
    drive, ClockOut, Cursor, DrivePolicy, Intake, Pace, Pacer, Turn,
};
use ratelab_runtime::runcore::{RestoreError, RunCore};
use ratelab_runtime::scheduler::{EndReason, RunEnd, VirtualScheduler};
use ratelab_runtime::telemetry::{Control, Speed, Telemetry};
use std::convert::Infallible;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

impl Engine {
    /// Run `core` under the virtual clock, from where it is, until the user moves on
    /// (`resumed`: it went on from the real clock, and starts unpaused): the one drive loop
    /// ([`drive`]) under the lab's policy ([`Paced`]). Returns what they asked next, how the
    /// run ended (interrupted now, unless it had ended) and the executors' figures.
    pub(super) fn virtual_run(
        &mut self,
        core: &mut RunCore,
        cfg: &RunConfig,
        recording: &Option<Recording>,
        ros2: Option<&ratelab_ros2::Bridge>,
        resumed: bool,
    ) -> Segment {
        let mut paced = Paced {
            handles: core.handles().clone(),
            paused: self.settings.start_paused && !resumed,
            step_pending: false,
            ended: core.end().cloned(),
            pacer: Pacer::new(core.now(), times(self.speed)),
            last_status: None,
            next: None,
            cfg,
            recording,
            offered: ros2.is_some(),
            engine: self,
        };
        let clock = ros2.map(|b| b as &dyn ClockOut);
        // No stop flag of its own: the lab's run is left by its controls (`Paced::leave`),
        // and an ended run is kept, to be scrubbed, until then.
        let Ok(_) = drive(core, &mut Cursor::default(), &mut paced, None, clock);
        // `drive` leaves only from an intake, after any end was told (`at_end`): `ended` has it.
        let Paced { next, ended, .. } = paced;
        self.leave(next.unwrap_or(Next::Quit), core.scheduler(), ended)
    }

    /// Apply `cmd` to the running graph at its next instant, as a replay would (a new plan
    /// runs from then on), and say what it did; a rate change also says where the node's
    /// ticks now fall and when a fresh run at it would fall.
    fn apply_live(
        &mut self,
        core: &mut RunCore,
        cmd: Command,
        cfg: &RunConfig,
        recording: &Option<Recording>,
        handles: &GraphHandles,
    ) {
        let at = core.scheduler().next_due().unwrap_or(core.now());
        let node = rate_target(&cmd, handles);
        let text = ratelab_runtime::telemetry::describe(&cmd);
        // A new plan (the executor key) runs from the next instant on,
        // as a replay applies it.
        let applied = self.apply_with(cmd, at, recording, true, |c| core.apply(c.clone()));
        if applied {
            let sched = core.scheduler();
            let said = match node.and_then(|n| phase_note(sched, handles, n)) {
                Some(note) => {
                    let said = format!("{text} · {note}");
                    let _ = self.tx.send(Telemetry::Applied(said.clone()));
                    said
                }
                None => text,
            };
            if node.is_some() {
                self.judge_fresh_run(cfg, handles, said);
            }
        }
    }

    /// The run's figures now: as it ended, or as far as it has run.
    fn figures_now(
        &self,
        cfg: &RunConfig,
        core: &RunCore,
        ended: Option<&RunEnd>,
    ) -> ratelab_core::metrics::Metrics {
        let end = ended.cloned().unwrap_or(RunEnd {
            at: core.now(),
            reason: EndReason::Interrupted,
        });
        let handles = core.handles().clone();
        let sched = core.scheduler();
        live_metrics(
            cfg,
            &handles,
            &end,
            sched.ticks(),
            None,
            sched.figures(end.at),
        )
    }

    /// Tell the front end the run has ended (`end`): its last callbacks, status and summary.
    fn tell_ended(&self, cfg: &RunConfig, core: &mut RunCore, end: &RunEnd, paused: bool) {
        let metrics = self.figures_now(cfg, core, Some(end));
        self.tell_status(core, paused);
        let _ = self.tx.send(Telemetry::Ended {
            metrics: Box::new(metrics),
            reason: end.reason.clone(),
        });
    }

    /// [`Control::Seek`] while paused. Forward, the run goes on to `to` (as steps do). Back —
    /// not while recording or offered to ROS 2, which keep the run as it ran — the run core
    /// restores and runs again to `to` with the step telemetry muted (the front end has those
    /// steps), the run's log keeps the branch's commands, and the front end is told
    /// [`Telemetry::Rewound`]; what runs next is a new branch. Back into a part of the run
    /// the real clock ran (which cannot run again), it goes to where that part began.
    fn seek(
        &mut self,
        core: &mut RunCore,
        to: Nanos,
        cfg: &RunConfig,
        recording: &Option<Recording>,
        offered: bool,
        ended: &mut Option<RunEnd>,
    ) {
        let back = to < core.now();
        if back && (recording.is_some() || offered) {
            let why = if offered {
                "offered to ROS 2"
            } else {
                "recorded"
            };
            let _ = self.tx.send(Telemetry::Error(format!(
                "scrubbing back is off while the run is {why}: it keeps the run as it ran"
            )));
            return;
        }
        if !back && ended.is_some() {
            return; // nothing runs after the end
        }
        self.muted.store(back, Ordering::Relaxed);
        let mut result = core.seek(to.min(cfg.duration));
        let mut skipped = None;
        if let Err(e @ RestoreError::RealPart { from, .. }) = &result {
            // Scrubbing back skips a part the real clock ran: to where it began.
            skipped = Some(format!("{e}: back to {from}, before it"));
            result = core.seek(*from);
        }
        self.muted.store(false, Ordering::Relaxed);
        if let Err(e) = result {
            let _ = self.tx.send(Telemetry::Error(e.to_string()));
            return;
        }
        let was_ended = ended.is_some();
        *ended = core.end().cloned().map(|end| lab_end(end, cfg, core));
        if back {
            let _ = self.tx.send(Telemetry::Rewound { at: core.now() });
            self.branch_log(core.applied(), core.now());
            if let Some(note) = skipped {
                let _ = self.tx.send(Telemetry::Applied(note));
            }
        }
        match ended.clone() {
            Some(end) if !was_ended => self.tell_ended(cfg, core, &end, true),
            _ => self.tell_status(core, true),
        }
    }

    /// Tell the front end the callbacks run since it was last told, then the status now.
    fn tell_status(&self, core: &mut RunCore, paused: bool) {
        let spans = core.scheduler_mut().take_spans();
        if !spans.is_empty() {
            let _ = self.tx.send(Telemetry::Callbacks(spans));
        }
        let sched = core.scheduler();
        self.status(sched.now(), paused, core.handles(), sched.skipped_ticks());
    }

    /// Leave the run for `next`: how it ended (interrupted now, unless it had ended) and
    /// the executors' figures.
    fn leave(&self, next: Next, sched: &VirtualScheduler, ended: Option<RunEnd>) -> Segment {
        let end = ended.unwrap_or(RunEnd {
            at: sched.now(),
            reason: EndReason::Interrupted,
        });
        (next, end, None, sched.figures(sched.now()))
    }
}

/// How the lab says a run ended: a run that reached its duration ends at its last instant.
fn lab_end(mut end: RunEnd, cfg: &RunConfig, core: &RunCore) -> RunEnd {
    if end.reason == EndReason::Duration {
        end.at = cfg.duration.min(core.now());
    }
    end
}

/// The node a rate command changes, if it is one.
fn rate_target(cmd: &Command, h: &GraphHandles) -> Option<usize> {
    match cmd {
        Command::SetControlHz { .. } => h.spec.chain.map(|c| c.policy.0),
        Command::SetSensorHz { .. } => h.spec.chain.map(|c| c.sensor.0),
        Command::SetNodeHz { node, .. } => h.spec.nodes.iter().position(|n| &n.name == node),
        _ => None,
    }
}

/// After a live rate change: a node keeps the phase its old rate left it (its next tick is
/// where the old period put it, then the new period on), so its ticks need not fall where a
/// run started at the new rate puts them (multiples of the period from 0), and its latency
/// can differ from `ratelab run`'s at that rate. Says so, with the offset and where its ticks
/// now fall against the sensor's (what its latency depends on), when it does (`63.333 ms off
/// a fresh run's phase · ticks 3.333 ms after the sensor's (r realigns)`: two parts of
/// the notice, so a narrow footer keeps the second).
fn phase_note(sched: &VirtualScheduler, h: &GraphHandles, node: usize) -> Option<String> {
    let period = h.rates.get(node)?.period();
    let next = sched.next_due_of(node)?;
    let off = Nanos(next.0 % period.0.max(1));
    (off.0 != 0).then(|| match after_sensor(sched, h, node, next) {
        Some(sensor) => format!("{off} off a fresh run's phase · {sensor} (r realigns)"),
        None => format!("{off} off a fresh run's phase (r realigns)"),
    })
}

/// Where node `node`'s next tick (at `next`) falls against the chain's sensor's ticks:
/// `ticks on the sensor's` (at the same instants, after the sensor by the tie-break order, so
/// it reads a fresh state) or `ticks 3.333 ms after the sensor's`. `None` for the sensor
/// itself or a graph without the chapter's chain.
fn after_sensor(
    sched: &VirtualScheduler,
    h: &GraphHandles,
    node: usize,
    next: Nanos,
) -> Option<String> {
    let sensor = h.spec.chain?.sensor.0;
    if sensor == node {
        return None;
    }
    let period = h.rates.get(sensor)?.period().0.max(1);
    let sensor_next = sched.next_due_of(sensor)?;
    let after = Nanos(
        (i128::from(next.0) - i128::from(sensor_next.0)).rem_euclid(i128::from(period)) as u64,
    );
    Some(if after.0 == 0 {
        "ticks on the sensor's".to_string()
    } else {
        format!("ticks {after} after the sensor's")
    })
}

/// The lab's drive policy: the keys' controls taken between instants, the run paced at the
/// chosen speed (or one actuator step at a time while paused), the status told every 33 ms,
/// and an ended run held, frozen and seekable, until the user moves on.
struct Paced<'a> {
    engine: &'a mut Engine,
    cfg: &'a RunConfig,
    recording: &'a Option<Recording>,
    /// Offered to ROS 2 (no scrubbing back).
    offered: bool,
    /// A seek back that replays builds a new graph: these are taken again after one.
    handles: GraphHandles,
    paused: bool,
    /// `.` while paused: run until the actuator has ticked once.
    step_pending: bool,
    /// How the run ended, as the lab says it ([`lab_end`]); `None` while it runs.
    ended: Option<RunEnd>,
    pacer: Pacer,
    /// When the status was last told (`None`: not yet).
    last_status: Option<Instant>,
    /// What the user asked next, once they have.
    next: Option<Next>,
}

/// The pacer's speed for the lab's `speed` (`None`: as fast as it runs).
fn times(speed: Speed) -> Option<f64> {
    match speed {
        Speed::Times(x) => Some(x),
        Speed::Max => None,
    }
}

impl Paced<'_> {
    /// Leave the run for `next`.
    fn leave(&mut self, next: Next) -> Intake {
        self.next = Some(next);
        Intake::Leave
    }

    /// One control from the keys (or from ROS 2's `param set`); `Some` when it leaves.
    fn control(&mut self, core: &mut RunCore, msg: Control) -> Option<Intake> {
        let e = &mut *self.engine;
        match msg {
            Control::Apply(cmd) => {
                if self.ended.is_none() {
                    e.apply_live(core, cmd, self.cfg, self.recording, &self.handles);
                } else {
                    e.defer(cmd, &self.handles);
                }
            }
            Control::Stall { node, duration } => {
                // From the instant the run takes up next, as `apply_live` applies it.
                if self.ended.is_none() {
                    let at = core.scheduler().next_due().unwrap_or(core.now());
                    let cmd = ratelab_runtime::command::stall_from(&node, at, duration);
                    e.apply_live(core, cmd, self.cfg, self.recording, &self.handles);
                } else {
                    e.stall_after_end(&node);
                }
            }
            Control::TogglePause => {
                self.paused = !self.paused;
                self.pacer.anchor(core.now());
            }
            Control::Step => self.step_pending |= self.paused,
            Control::Seek(to) => {
                if self.paused {
                    e.seek(
                        core,
                        to,
                        self.cfg,
                        self.recording,
                        self.offered,
                        &mut self.ended,
                    );
                    self.handles = core.handles().clone();
                }
                // Taken, moved or not: a front end counts these answers.
                let _ = e.tx.send(Telemetry::Sought { at: core.now() });
            }
            Control::SetSpeed(s) => {
                e.speed = s;
                self.pacer.set_speed(core.now(), times(s));
            }
            Control::Reset { next_seed } => return Some(self.leave(Next::Reset { next_seed })),
            Control::SwitchClock => return Some(self.leave(Next::SwitchClock)),
            Control::Reload { file } => {
                // Loaded and judged on a thread of its own: taken up in `intake` once it has.
                let old = e.figures_now(self.cfg, core, self.ended.as_ref());
                let topics = core.handles().spec.topics.iter();
                let topics = topics.map(|t| t.name.clone()).collect();
                let old = RunFigures::of(&old, topics, e.opening.ticks());
                e.reload(self.cfg, &file, Some(old));
            }
            Control::Quit => return Some(self.leave(Next::Quit)),
        }
        None
    }
}

impl DrivePolicy<Nanos, RunCore> for Paced<'_> {
    type Error = Infallible;

    /// The run's end first, if the core has ended and `at_end` has not been told (so that
    /// no control is taken as if it ran on); then the controls that have come (waiting up to 30 ms for one while
    /// paused, with no step pending, or ended), a save whose code has loaded, the status
    /// every 33 ms.
    fn intake(&mut self, core: &mut RunCore) -> Intake {
        if self.ended.is_none() {
            if let Some(end) = core.end().cloned() {
                self.at_end(core, &end);
            }
        }
        loop {
            let wait = (self.paused && !self.step_pending) || self.ended.is_some();
            let msg = if wait {
                match self.engine.rx.recv_timeout(Duration::from_millis(30)) {
                    Ok(m) => m,
                    Err(RecvTimeoutError::Timeout) => break,
                    Err(RecvTimeoutError::Disconnected) => return self.leave(Next::Quit),
                }
            } else {
                match self.engine.rx.try_recv() {
                    Ok(m) => m,
                    Err(_) => break,
                }
            };
            if let Some(left) = self.control(core, msg) {
                return left;
            }
            if self.step_pending {
                break;
            }
        }
        // A save whose code has loaded (and been judged): its run is the next.
        if let Some(ready) = self.engine.reload_ready() {
            let next = self.engine.as_next(self.cfg, ready);
            return self.leave(next);
        }
        if self
            .last_status
            .is_none_or(|at| at.elapsed() >= Duration::from_millis(33))
        {
            self.engine.tell_status(core, self.paused);
            self.last_status = Some(Instant::now());
        }
        if self.ended.is_some() || (self.paused && !self.step_pending) {
            Intake::Hold
        } else {
            Intake::Go
        }
    }

    /// One step runs at once; otherwise at the chosen speed.
    fn pace(&mut self, t: Nanos) -> Pace {
        if self.step_pending {
            Pace::Now
        } else {
            self.pacer.pace(t)
        }
    }

    /// A step is done once the actuator has ticked.
    fn taken(
        &mut self,
        _core: &mut RunCore,
        _index: u64,
        _t: Nanos,
        ticked: u64,
    ) -> Result<Turn, Infallible> {
        let actuator_bit = 1u64 << (self.handles.spec.actuator.0 % 64);
        if ticked & actuator_bit != 0 {
            self.step_pending = false;
        }
        Ok(Turn::Go)
    }

    /// The run is told it ended, and held: frozen, and scrubbed until the user moves on.
    /// `drive` asks it right after an instant that ended the run, and of a run it finds
    /// ended; `intake` holds a run once told.
    fn at_end(&mut self, core: &mut RunCore, end: &RunEnd) -> Intake {
        let end = lab_end(end.clone(), self.cfg, core);
        self.engine.tell_ended(self.cfg, core, &end, self.paused);
        self.ended = Some(end);
        Intake::Hold
    }
}
