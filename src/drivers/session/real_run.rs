//! A real-clock run in the lab: the run core's graph on its executor's threads
//! ([`ratelab_runtime::runcore::RunCore::run_real`]), controls applied at once (from each node's next
//! tick).

use super::engine::{live_metrics, Engine, Next, Segment};
use super::reload::{Ready, RealExit};
use super::trial::Restart;
use crate::run::Command;
use crossbeam_channel::RecvTimeoutError;
use ratelab_core::time::Nanos;
use ratelab_recording::Recording;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::runcore::RunCore;
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
    /// the user moves on or a save restarts nodes in place.
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
        let stop = StopFlag::new();
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
        // The run time now: the real clock reads `from` at its start.
        let start = Instant::now();
        let now = || from.saturating_add(Nanos::from(start.elapsed()));
        // A runner that panicked (its node threads could not start) took the graph's nodes
        // with it: the run has ended, whatever the user asks next.
        let mut lost = false;
        let mut restart = None;
        let part = std::thread::scope(|scope| {
            let runner = std::thread::Builder::new()
                .name("real-clock".into())
                .spawn_scoped(scope, || core.run_real(None, &stop, &opts))
                .expect("spawning the real-clock runner");
            let mut runner = Some(runner);
            let mut last_status = Instant::now();
            let mut result: Option<RunEnd> = None;
            let mut timing = None;
            let mut exec = None;
            loop {
                if result.is_none() && runner.as_ref().is_some_and(|r| r.is_finished()) {
                    let Ok(run) = runner.take().expect("checked").join() else {
                        lost = true;
                        let end = RunEnd {
                            at: now(),
                            reason: EndReason::Interrupted,
                        };
                        let _ = self.tx.send(Telemetry::Error(
                            "the real clock's runner failed: the run has ended (r starts the next)"
                                .into(),
                        ));
                        result = Some(end);
                        continue;
                    };
                    let end = run.end.clone();
                    let ticks: Vec<u64> = run
                        .timing
                        .iter()
                        .zip(&ticked)
                        .map(|(t, before)| before + t.ticks)
                        .collect();
                    timing = Some(run.timing);
                    exec = run.exec;
                    let metrics =
                        live_metrics(cfg, &handles, &end, &ticks, timing.clone(), exec.clone());
                    let _ = self.tx.send(Telemetry::Ended {
                        metrics: Box::new(metrics),
                        reason: end.reason.clone(),
                    });
                    result = Some(end);
                }
                let msg = self.rx.recv_timeout(Duration::from_millis(30));
                let ran = Stretch {
                    cfg,
                    handles: &handles,
                    running: &running,
                    recording,
                    ended: result.is_some(),
                };
                let next = match self.real_control(msg, now(), &ran) {
                    Some(next) => Some(next),
                    // A save whose code has loaded, taken up now.
                    None => self.real_ready(now(), &ran, &mut restart),
                };
                if let Some(next) = next {
                    stop.stop();
                    let end = match (result, runner.take()) {
                        (Some(end), _) => end,
                        (None, Some(r)) => match r.join() {
                            Ok(run) => {
                                timing = Some(run.timing);
                                exec = run.exec;
                                run.end
                            }
                            Err(_) => {
                                lost = true;
                                RunEnd {
                                    at: now(),
                                    reason: EndReason::Interrupted,
                                }
                            }
                        },
                        (None, None) => RunEnd {
                            at: now(),
                            reason: EndReason::Interrupted,
                        },
                    };
                    return (next, end, timing, exec);
                }
                if last_status.elapsed() >= Duration::from_millis(33) {
                    // Once the run has ended (a fall, a watchdog, a failed node), its clock
                    // stops where it ended: the lab shows that instant, not wall time
                    // running on.
                    let shown = result.as_ref().map_or_else(now, |end| end.at);
                    self.status(shown, pause.load(Ordering::SeqCst), &handles, None);
                    last_status = Instant::now();
                }
            }
        });
        if lost {
            core.interrupt();
        }
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
            Ok(Control::Step | Control::Seek(_) | Control::SetSpeed(_)) => {
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
