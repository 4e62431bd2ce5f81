//! A run under the real clock, watched: the graph handed to the real clock's threads
//! ([`RunCore::run_real`], on a runner thread of its own), which run it tick by tick with no
//! drive loop, while the calling thread takes the front end's controls ([`RealPolicy`])
//! until the run ends and the policy lets it go, or the policy leaves (which stops the
//! run). The lab's real-clock stretches and each process of a launch under the real clock
//! go through it.
//!
//! Commands cannot go through the core here (the runner has it): a policy applies them to
//! the graph's handles ([`crate::graph::GraphHandles`], cloned before), at the run time the
//! wall gives.

use super::Intake;
use crate::runcore::{RealEnd, RunCore};
use crate::scheduler::{RealOptions, StopFlag};

/// What a front end supplies to [`watch_real`].
pub trait RealPolicy {
    /// While the graph runs (`ended`: the runner has returned, and the policy holds the
    /// ended run): take controls, waiting for them at most a few tens of ms.
    /// [`Intake::Leave`] stops the run and returns; `Go` and `Hold` come back.
    fn intake(&mut self, ended: bool) -> Intake;

    /// The runner returned without being asked (the duration, a fall, a failed node):
    /// `run` is how it went, or `None` when the runner itself failed (its node threads
    /// could not start; the run's nodes are lost with it). [`Intake::Leave`] (the default)
    /// returns; `Hold` goes on taking controls for the ended run.
    fn at_end(&mut self, _run: Option<&RealEnd>) -> Intake {
        Intake::Leave
    }
}

/// Run `core`'s graph (`part`: only these nodes, graph indices, ascending; `None`: all)
/// under the real clock with `opts`, on a runner thread named `real-clock`, while `policy`
/// takes controls on this thread ([`RealPolicy`]); `stop` set from outside stops the run as
/// the policy leaving does. Returns how the run went, or `None` when the runner failed: the
/// core is then ended as interrupted ([`RunCore::interrupt`]), its nodes gone.
pub fn watch_real<P: RealPolicy + ?Sized>(
    core: &mut RunCore,
    part: Option<&[usize]>,
    opts: &RealOptions,
    policy: &mut P,
    stop: &StopFlag,
) -> Option<RealEnd> {
    let run_stop = StopFlag::new();
    let ran = std::thread::scope(|scope| {
        // A policy that panics still stops the run, so that the scope's join returns.
        let _stops = StopOnDrop(&run_stop);
        let runner = std::thread::Builder::new()
            .name("real-clock".into())
            .spawn_scoped(scope, || core.run_real(part, &run_stop, opts));
        let mut runner = runner.ok();
        // How the run went once the runner has returned (`Some(None)`: it failed).
        let mut held: Option<Option<RealEnd>> = runner.is_none().then_some(None);
        if held.is_some() && policy.at_end(None) == Intake::Leave {
            return None;
        }
        loop {
            if let Some(r) = runner.take_if(|r| r.is_finished()) {
                let run = r.join().ok();
                if policy.at_end(run.as_ref()) == Intake::Leave {
                    return run;
                }
                held = Some(run);
            }
            let leave = stop.is_stopped() || policy.intake(held.is_some()) == Intake::Leave;
            if leave {
                run_stop.stop();
                return match (held, runner) {
                    (Some(run), _) => run,
                    (None, Some(r)) => r.join().ok(),
                    (None, None) => None,
                };
            }
        }
    });
    if ran.is_none() {
        core.interrupt();
    }
    ran
}

/// Stops the run when dropped: on return, and while unwinding from a policy's panic.
struct StopOnDrop<'a>(&'a StopFlag);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{ClockKind, RunConfig};
    use crate::runcore::CoreOptions;
    use crate::scheduler::EndReason;
    use ratelab_core::time::Nanos;
    use std::time::{Duration, Instant};

    fn core(duration: Nanos) -> (RunCore, RunConfig) {
        let cfg = RunConfig {
            clock: ClockKind::Real,
            duration,
            ..RunConfig::default()
        };
        let c = RunCore::new(
            &cfg,
            Box::new(crate::policy::Scripted),
            CoreOptions::default(),
        )
        .unwrap();
        (c, cfg)
    }

    /// Leaves after `leave_after` intakes (`None`: never), holding the ended run for
    /// `hold` more.
    struct Count {
        intakes: usize,
        leave_after: Option<usize>,
        ends: Vec<Option<EndReason>>,
        hold: usize,
    }
    impl RealPolicy for Count {
        fn intake(&mut self, ended: bool) -> Intake {
            self.intakes += 1;
            std::thread::sleep(Duration::from_millis(5));
            if ended {
                self.hold = self.hold.saturating_sub(1);
                return if self.hold == 0 {
                    Intake::Leave
                } else {
                    Intake::Hold
                };
            }
            if self.leave_after.is_some_and(|n| self.intakes >= n) {
                Intake::Leave
            } else {
                Intake::Go
            }
        }
        fn at_end(&mut self, run: Option<&RealEnd>) -> Intake {
            self.ends.push(run.map(|r| r.end.reason.clone()));
            if self.hold > 0 {
                Intake::Hold
            } else {
                Intake::Leave
            }
        }
    }

    #[test]
    fn a_run_to_its_duration_is_told_its_end_and_held_until_the_policy_leaves() {
        let (mut c, _) = core(Nanos(200_000_000));
        let real = RealOptions::default();
        // Leaves after 10 s at the latest: a loop that forgot the end fails, not hangs.
        let mut p = Count {
            intakes: 0,
            leave_after: Some(2_000),
            ends: vec![],
            hold: 3,
        };
        let r = watch_real(&mut c, None, &real, &mut p, &StopFlag::new()).unwrap();
        assert_eq!(r.end.reason, EndReason::Duration);
        assert_eq!(p.ends, vec![Some(EndReason::Duration)], "told once");
        assert_eq!(p.hold, 0, "held for three intakes after the end");
        assert!(c.now() > Nanos::ZERO);
    }

    #[test]
    fn leaving_stops_the_run_at_once_and_returns_it_interrupted_not_ended() {
        let (mut c, _) = core(Nanos(60 * Nanos::SECOND.0));
        let mut p = Count {
            intakes: 0,
            leave_after: Some(10),
            ends: vec![],
            hold: 0,
        };
        let began = Instant::now();
        let r = watch_real(
            &mut c,
            None,
            &RealOptions::default(),
            &mut p,
            &StopFlag::new(),
        )
        .unwrap();
        assert!(
            began.elapsed() < Duration::from_secs(30),
            "stopped, not run out"
        );
        assert_eq!(r.end.reason, EndReason::Interrupted);
        assert!(p.ends.is_empty(), "the policy left: no end to tell");
        assert!(
            c.end().is_none(),
            "a stop by the front end leaves the core to go on"
        );
        let stop = StopFlag::new();
        stop.stop();
        let mut p = Count {
            intakes: 0,
            leave_after: None,
            ends: vec![],
            hold: 0,
        };
        let r = watch_real(&mut c, None, &RealOptions::default(), &mut p, &stop).unwrap();
        assert_eq!(
            r.end.reason,
            EndReason::Interrupted,
            "a stop from outside too"
        );
    }
}
