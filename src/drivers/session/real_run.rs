//! A real-clock run in the lab: the run core's graph on its executor's threads
//! ([`ratelab_runtime::runcore::RunCore::run_real`]), controls applied at once (from each node's next
//! tick).

use super::engine::{live_metrics, Engine, Next, Segment};
use super::reload::{Ready, RealExit};
use super::trial::Restart;
use crate::run::Command;
use crossbeam_channel::RecvTimeoutError;
use ratelab_core::executor::ExecFigures;
use ratelab_core::metrics::NodeTiming;
use ratelab_core::time::Nanos;
use ratelab_recording::Recording;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::runcore::drive::{watch_real, Intake, RealPolicy};
use ratelab_runtime::runcore::{RealEnd, RunCore};
use ratelab_runtime::scheduler::{EndReason, RealOptions, RunEnd, StopFlag};
use ratelab_runtime::telemetry::{Control, Telemetry};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What a stretch of the real clock runs ([`Engine::real_once`]).
struct Stretch<'a> {
    cfg: &'a RunConfig,
    handles: &'a ratelab_runtime::graph::GraphHandles,
    /// The run's graph as its nodes were built.
    running: &'a ratelab_runtime::graph::GraphSpec,
    recording: &'a Option<Recording>,
    /// The run has ended (keys set the next run).
    ended: bool,
}

impl Engine {
    /// Run `core` under the real clock, from where it is (t = 0, or the instant the
    /// virtual clock reached: a clock switch in place), until the user moves on. Returns
    /// what they asked next, how the run ended, each node's timing and the executors'
    /// figures. The core comes back at the time the real clock stopped. A saved node's
    /// code restarts that node in place ([`Engine::reload_in_place`]): the real clock stops,
    /// the node is built again, and the run goes on from where it was.
    pub(super) fn real_run(
        &mut self,
        core: &mut RunCore,
        cfg: &RunConfig,
        recording: &Option<Recording>,
    ) -> Segment {
        if let Some(Err(e)) = cfg.rt_priority.map(ratelab_core::realtime::probe_fifo) {
            // Told now, not only when the run ends: node threads inherit this thread's
            // privileges, so they will be refused the same way.
            let _ = self.tx.send(Telemetry::Applied(format!(
                "warning: node threads keep their default policy: {e}"
            )));
        }
        loop {
            match self.real_once(core, cfg, recording) {
                RealExit::Done(part) => return part,
                RealExit::Restart(r) => {
                    let at = core.now();
                    // Restarted in place: an event of the run, marked as a change.
                    if let (Some(line), Some(rec)) = (self.restart_in_place(core, r), recording) {
                        rec.reloaded(at, &line);
                    }
                }
            }
        }
    }

    /// One stretch of [`Engine::real_run`]: the real clock from where the core is, until
    /// the user moves on or a save restarts nodes in place: the real clock's threads run the
    /// graph while [`watch_real`] takes the lab's controls ([`RealPaced`]).
    fn real_once(
        &mut self,
        core: &mut RunCore,
        cfg: &RunConfig,
        recording: &Option<Recording>,
    ) -> RealExit {
        let handles = core.handles().clone();
        let running = core.config().graph.clone();
        let from = core.now();
        // Ticks so far (under the virtual clock, or earlier parts under this one).
        let ticked = core.scheduler().ticks().to_vec();
        // Only a run that starts here starts paused (a lab started with --paused).
        let pause = Arc::new(AtomicBool::new(
            self.settings.start_paused && from == Nanos::ZERO,
        ));
        let tx = self.tx.clone();
        let rec = recording.clone();
        let opts = RealOptions {
            on_tick: Some(Arc::new(
                move |t: &ratelab_runtime::scheduler::TickReport<'_>| {
                    let _ = tx.send(Telemetry::NodeTick {
                        node: t.node,
                        now: t.now,
                        lateness: t.lateness,
                        took: t.took,
                    });
                    if let Some(r) = &rec {
                        r.real_tick(t);
                    }
                },
            )),
            pause: Some(pause.clone()),
            ..crate::run::real_options(cfg)
        };
        let mut policy = RealPaced {
            stretch: Stretch {
                cfg,
                handles: &handles,
                running: &running,
                recording,
                ended: false,
            },
            from,
            start: Instant::now(),
            ticked: &ticked,
            pause: &pause,
            last_status: Instant::now(),
            told: None,
            next: None,
            restart: None,
            engine: self,
        };
        // No stop of its own: the lab's run is left by its controls.
        let ran = watch_real(core, None, &opts, &mut policy, &StopFlag::new());
        let now = policy.now();
        let RealPaced {
            told,
            next,
            restart,
            ..
        } = policy;
        let next = next.unwrap_or(Next::Quit);
        let part = match (told, ran) {
            (Some((end, timing, exec)), _) => (next, end, timing, exec),
            (None, Some(run)) => (next, run.end, Some(run.timing), run.exec),
            (None, None) => {
                let end = RunEnd {
                    at: now,
                    reason: EndReason::Interrupted,
                };
                (next, end, None, None)
            }
        };
        match restart {
            Some(r) if core.end().is_none() => RealExit::Restart(r),
            // The run ended as the file was saved: the new code (it loads) starts the next
            // run.
            Some(r) => {
                let next = self.as_next(cfg, Ready::Restart(r));
                RealExit::Done((next, part.1, part.2, part.3))
            }
            None => RealExit::Done(part),
        }
    }

    /// What the user asked during a stretch of the real clock ([`Engine::real_once`]), at
    /// run time `now`: `Some(next)` ends the stretch. A save starts its code loading on a
    /// thread of its own ([`Engine::real_ready`] takes it up).
    fn real_control(
        &mut self,
        msg: Result<Control, RecvTimeoutError>,
        now: Nanos,
        ran: &Stretch<'_>,
    ) -> Option<Next> {
        match msg {
            Ok(Control::Apply(cmd)) => {
                if !ran.ended {
                    self.apply_real(cmd, now, ran.cfg, ran.handles, ran.recording);
                } else {
                    self.defer(cmd, ran.handles);
                }
                None
            }
            Ok(Control::Stall { node, duration }) => {
                // From the run time the wall gives now, as `apply_real` applies it.
                if !ran.ended {
                    let cmd = ratelab_runtime::command::stall_from(&node, now, duration);
                    self.apply_real(cmd, now, ran.cfg, ran.handles, ran.recording);
                } else {
                    self.stall_after_end(&node);
                }
                None
            }
            Ok(Control::TogglePause) => {
                // Wall time cannot stop: a paused real-clock run would only skip
                // ticks while its clock (and every latency) ran on. Refused, and
                // said so.
                let _ = self.tx.send(Telemetry::Error(
                    "pause is for the virtual clock: real time does not stop (c switches clock)"
                        .into(),
                ));
                None
            }
            Ok(c @ (Control::Step | Control::Seek(_) | Control::SetSpeed(_))) => {
                if let Control::Seek(_) = c {
                    // Every seek is answered (a front end counts them); this one stays put.
                    let _ = self.tx.send(Telemetry::Sought { at: now });
                }
                let _ = self.tx.send(Telemetry::Error(
                    "single-step, scrubbing and speed apply to the virtual clock only (c switches clock)".into(),
                ));
                None
            }
            Ok(Control::Reset { next_seed }) => Some(Next::Reset { next_seed }),
            Ok(Control::SwitchClock) => Some(Next::SwitchClock),
            // A run going on restarts the saved code's nodes in place; one that
            // ended starts again with the new code (if it loads).
            Ok(Control::Reload { file }) if !ran.ended => {
                self.reload_in_place(ran.cfg, ran.running, ran.handles, &file);
                None
            }
            Ok(Control::Reload { file }) => {
                self.reload(ran.cfg, &file, None);
                None
            }
            Ok(Control::Quit) | Err(RecvTimeoutError::Disconnected) => Some(Next::Quit),
            Err(RecvTimeoutError::Timeout) => None,
        }
    }

    /// A save whose code has loaded ([`Engine::reload_ready`]), taken up during a stretch
    /// of the real clock at run time `now`: `Some(next)` ends the stretch (`restart` set:
    /// for a restart in place, the real clock standing still while the nodes load again);
    /// a brain is swapped in at once. A run that has ended starts again with the new code.
    fn real_ready(
        &mut self,
        now: Nanos,
        ran: &Stretch<'_>,
        restart: &mut Option<Box<Restart>>,
    ) -> Option<Next> {
        match self.reload_ready()? {
            Ready::Restart(r) if !ran.ended => {
                *restart = Some(r);
                Some(Next::Quit) // the real clock stops for the restart
            }
            Ready::Brain {
                name,
                swap,
                pinned_before,
            } if !ran.ended => {
                if self.apply(swap, now, ran.handles, ran.recording) {
                    self.brain_reloaded(&name);
                } else {
                    super::reload::repin(pinned_before);
                }
                None
            }
            ready => Some(self.as_next(ran.cfg, ready)),
        }
    }

    /// Apply `cmd` to the running real-clock graph at `now`: a rate at once (and when a
    /// fresh run at it would fall), the executor for the next run (its threads are made at
    /// a run's start), the rest at once.
    fn apply_real(
        &mut self,
        cmd: Command,
        now: Nanos,
        cfg: &RunConfig,
        handles: &ratelab_runtime::graph::GraphHandles,
        recording: &Option<Recording>,
    ) {
        if let Command::SetPhase { .. } = cmd {
            // Each node's thread keeps the grid it started on.
            let _ = self.tx.send(Telemetry::Error(
                "a phase change applies under the virtual clock (c switches clock); a real-clock run keeps --phase-offset-ms".into(),
            ));
            return;
        }
        let rate = matches!(
            cmd,
            Command::SetControlHz { .. } | Command::SetSensorHz { .. } | Command::SetNodeHz { .. }
        );
        let text = ratelab_runtime::telemetry::describe(&cmd);
        let executor = matches!(cmd, Command::SetExecutor { .. });
        let applied = if executor {
            self.apply_for_next_run(cmd, now, handles, recording)
        } else {
            self.apply(cmd, now, handles, recording)
        };
        if applied {
            if rate {
                self.judge_fresh_run(cfg, handles, text);
            } else if executor {
                // The real clock's threads are made when a run starts.
                let _ = self.tx.send(Telemetry::Applied(format!(
                    "{text} (from the next run: r; the real clock's threads are made at the start)"
                )));
            }
        }
    }
}

/// How a stretch of the real clock ended, as the lab told it: the end, each node's timing
/// and the executors' figures.
type Told = (RunEnd, Option<Vec<NodeTiming>>, Option<ExecFigures>);

/// The lab's policy for a stretch of the real clock ([`watch_real`]): the keys' controls
/// applied at once to the running graph, a save's code taken up when it has loaded, the
/// status every 33 ms, and an ended run held (its clock stopped where it ended) until the
/// user moves on.
struct RealPaced<'a> {
    engine: &'a mut Engine,
    stretch: Stretch<'a>,
    /// The run time the real clock read at `start`.
    from: Nanos,
    start: Instant,
    /// Each node's ticks before this stretch.
    ticked: &'a [u64],
    /// The run's pause (only a run started paused at t = 0 has one set).
    pause: &'a AtomicBool,
    last_status: Instant,
    /// How the run ended, once the runner has returned and the lab has told it.
    told: Option<Told>,
    /// What the user asked next, once they have.
    next: Option<Next>,
    /// A save whose nodes restart in place.
    restart: Option<Box<Restart>>,
}

impl RealPaced<'_> {
    /// The run time now: the real clock read `from` at `start`.
    fn now(&self) -> Nanos {
        self.from.saturating_add(Nanos::from(self.start.elapsed()))
    }
}

impl RealPolicy for RealPaced<'_> {
    fn intake(&mut self, ended: bool) -> Intake {
        self.stretch.ended = ended;
        let msg = self.engine.rx.recv_timeout(Duration::from_millis(30));
        let now = self.now();
        let next = match self.engine.real_control(msg, now, &self.stretch) {
            Some(next) => Some(next),
            // A save whose code has loaded, taken up now.
            None => self
                .engine
                .real_ready(now, &self.stretch, &mut self.restart),
        };
        if let Some(next) = next {
            self.next = Some(next);
            return Intake::Leave;
        }
        if self.last_status.elapsed() >= Duration::from_millis(33) {
            // Once the run has ended (a fall, a watchdog, a failed node), its clock stops
            // where it ended: the lab shows that instant, not wall time running on.
            let shown = self.told.as_ref().map_or(now, |(end, ..)| end.at);
            let paused = self.pause.load(Ordering::SeqCst);
            self.engine
                .status(shown, paused, self.stretch.handles, None);
            self.last_status = Instant::now();
        }
        Intake::Go
    }

    /// The run ended on its own: the front end is told how (or that the runner failed),
    /// and the ended run is held.
    fn at_end(&mut self, run: Option<&RealEnd>) -> Intake {
        let told = match run {
            Some(run) => {
                let end = run.end.clone();
                let ticks: Vec<u64> = run
                    .timing
                    .iter()
                    .zip(self.ticked)
                    .map(|(t, before)| before + t.ticks)
                    .collect();
                let (timing, exec) = (Some(run.timing.clone()), run.exec.clone());
                let cfg = self.stretch.cfg;
                let handles = self.stretch.handles;
                let metrics =
                    live_metrics(cfg, handles, &end, &ticks, timing.clone(), exec.clone());
                let _ = self.engine.tx.send(Telemetry::Ended {
                    metrics: Box::new(metrics),
                    reason: end.reason.clone(),
                });
                (end, timing, exec)
            }
            None => {
                let _ = self.engine.tx.send(Telemetry::Error(
                    "the real clock's runner failed: the run has ended (r starts the next)".into(),
                ));
                let end = RunEnd {
                    at: self.now(),
                    reason: EndReason::Interrupted,
                };
                (end, None, None)
            }
        };
        self.told = Some(told);
        Intake::Hold
    }
}
