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
use ratelab_runtime::runcore::{RestoreError, RunCore, Step};
use ratelab_runtime::scheduler::{EndReason, RunEnd, VirtualScheduler};
use ratelab_runtime::telemetry::{Control, Speed, Telemetry};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

impl Engine {
    /// Run `core` under the virtual clock, from where it is, until the user moves on
    /// (`resumed`: it went on from the real clock, and starts unpaused). Returns what they
    /// asked next, how the run ended (interrupted now, unless it had ended) and the
    /// executors' figures.
    pub(super) fn virtual_run(
        &mut self,
        core: &mut RunCore,
        cfg: &RunConfig,
        recording: &Option<Recording>,
        ros2: Option<&ratelab_ros2::Bridge>,
        resumed: bool,
    ) -> Segment {
        // A seek back that replays builds a new graph: these are taken again after one.
        let mut handles = core.handles().clone();
        let mut paused = self.settings.start_paused && !resumed;
        let mut step_pending = false;
        let mut ended: Option<RunEnd> = core.end().cloned();
        // Pacing anchor: virtual time `anchor_v` corresponds to wall instant `anchor_w`.
        let mut anchor_v = core.now();
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
                            return self.leave(Next::Quit, core.scheduler(), ended)
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
                            self.apply_live(core, cmd, cfg, recording, &handles);
                        } else {
                            self.defer(cmd, &handles);
                        }
                    }
                    Control::TogglePause => {
                        paused = !paused;
                        anchor_v = core.now();
                        anchor_w = Instant::now();
                    }
                    Control::Step => {
                        if paused {
                            step_pending = true;
                        }
                    }
                    Control::Seek(to) => {
                        if paused {
                            self.seek(core, to, cfg, recording, ros2.is_some(), &mut ended);
                            handles = core.handles().clone();
                        }
                    }
                    Control::SetSpeed(s) => {
                        self.speed = s;
                        anchor_v = core.now();
                        anchor_w = Instant::now();
                    }
                    Control::Reset { next_seed } => {
                        return self.leave(Next::Reset { next_seed }, core.scheduler(), ended)
                    }
                    Control::SwitchClock => {
                        return self.leave(Next::SwitchClock, core.scheduler(), ended)
                    }
                    Control::Reload { file } => {
                        // Loaded and judged on a thread of its own: taken up below once it has.
                        let old = self.figures_now(cfg, core, ended.as_ref());
                        let topics = core.handles().spec.topics.iter();
                        let topics = topics.map(|t| t.name.clone()).collect();
                        let old = RunFigures::of(&old, topics, self.opening.ticks());
                        self.reload(cfg, &file, Some(old));
                    }
                    Control::Quit => return self.leave(Next::Quit, core.scheduler(), ended),
                }
                if step_pending {
                    break;
                }
            }
            // A save whose code has loaded (and been judged): its run is the next.
            if let Some(ready) = self.reload_ready() {
                let next = self.as_next(cfg, ready);
                return self.leave(next, core.scheduler(), ended);
            }
            if last_status.elapsed() >= Duration::from_millis(33) {
                self.tell_status(core, paused);
                last_status = Instant::now();
            }
            if ended.is_some() || (paused && !step_pending) {
                continue;
            }
            // Which instants may run now?
            let target = if step_pending {
                None // one actuator step: until the actuator ticks
            } else {
                match self.speed {
                    Speed::Max => None,
                    Speed::Times(x) => {
                        Some(anchor_v + Nanos((anchor_w.elapsed().as_nanos() as f64 * x) as u64))
                    }
                }
            };
            if let Some(end) = run_instants(core, target, &mut step_pending, ros2) {
                ended = Some(lab_end(end, cfg, core));
            }
            if let Some(end) = &ended {
                self.tell_ended(cfg, core, end, paused);
                continue;
            }
            // Sleep until the next instant is due on the wall (or a few ms at most).
            if let (Some(due), Speed::Times(x)) = (core.next_instant(), self.speed) {
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

/// Run instants of `core` up to `target` (`None`: no bound), or, with `step_pending`, until
/// the actuator has ticked once (then `step_pending` is cleared), for a few milliseconds at
/// most so that the lab stays responsive at max speed. Each instant's time goes to the
/// ROS 2 bridge's `/clock` first. Returns how the run ended, if it did.
fn run_instants(
    core: &mut RunCore,
    target: Option<Nanos>,
    step_pending: &mut bool,
    ros2: Option<&ratelab_ros2::Bridge>,
) -> Option<RunEnd> {
    let actuator_bit = 1u64 << (core.handles().spec.actuator.0 % 64);
    let budget = Instant::now();
    loop {
        if let Some(due) = core.next_instant() {
            if target.is_some_and(|t| due > t) {
                return None;
            }
            if let Some(b) = ros2 {
                b.clock(due);
            }
        }
        let actuator_ticked = match core.step() {
            Step::Ran { ticked, .. } => ticked & actuator_bit != 0,
            Step::Ended(end) => return Some(end),
        };
        if *step_pending && actuator_ticked {
            *step_pending = false;
            return None;
        }
        // Stay responsive at max speed: come back for controls every few ms.
        if budget.elapsed() > Duration::from_millis(8) {
            return None;
        }
    }
}
