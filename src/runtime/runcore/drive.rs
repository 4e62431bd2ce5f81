//! One drive loop for a run under the virtual clock, instant by instant: [`drive`] owns the
//! order of what happens around an instant (the stop flag, the commands taken between
//! instants, pacing against the wall, `/clock`, the end), and a [`DrivePolicy`] supplies only
//! what differs between front ends — which commands come in, how fast, what is told after.
//!
//! Every front end that steps a [`RunCore`] goes through it: the headless run and everything
//! built on it (`ratelab_drivers::run`: `sweep`, `cliff`, `bench`, `replay`, the exercises), the
//! lab's trial judge, ex13's count of `/clock` and the lab's paced session
//! (`ratelab_drivers::session`). Under the real clock, [`drive_real`] is the same loop's
//! other mode: the graph on the real clock's threads, the front end's controls taken on the
//! calling thread ([`RealPolicy`]): the lab's real-clock stretches and each process of a
//! launch. A run across processes under the virtual clock goes event by event: its event
//! mode, [`drive_events`], takes each event from a source an [`EventPolicy`] supplies (run
//! here, or from another process's report), for a process's lockstep and for the launcher
//! that follows the processes.
//!
//! # The order around an instant
//! 1. The stop flag: set, the run ends as interrupted at the newest instant run.
//! 2. [`DrivePolicy::intake`]: commands and controls, applied between instants (a command
//!    applied here takes effect before the next instant and is logged at it,
//!    [`RunCore::apply`]). `Hold` goes back to 1 (the policy waited), `Leave` returns
//!    [`Drove::Left`] with the run *not* ended (the lab's clock switch goes on with it).
//! 3. The end: once the run has ended, [`DrivePolicy::at_end`] says whether to hold (the lab
//!    keeps an ended run, which a seek back can take up again) or to return.
//! 4. Pacing ([`DrivePolicy::pace`]) for the next instant; a sleep goes back to 1, so commands
//!    and the stop flag are seen while waiting.
//! 5. The instant made ready: the commands scheduled at or before it applied
//!    ([`crate::command::TimedCommand`]). A phase change may move it later; then it is paced
//!    again, with no intake, since a command taken now would be logged after the scheduled
//!    ones of its instant, where a replay puts it before them.
//! 6. [`DrivePolicy::starting`] and `/clock` ([`ClockOut`]) told the instant that runs,
//!    the instant run, and [`DrivePolicy::ran`] told which nodes ticked.
//!
//! Pacing and `/clock` change only *when* an instant runs, never what it is: a driven run
//! equals [`RunCore::step`] called to the end, byte for byte (tests below).

mod events;
mod real;
pub use events::{drive_events, Cursor, Drew, EventOrder, EventPolicy, Taken, Turn};
pub use real::{drive_real, RealPolicy};

use super::{RunCore, Step};
use crate::scheduler::{RunEnd, StopFlag};
use ratelab_core::time::Nanos;
use std::time::{Duration, Instant};

/// The longest a pacing sleep lasts before the loop looks at its stop flag and commands
/// again: 10 ms.
pub const MAX_PACING_SLEEP: Duration = Duration::from_millis(10);

/// Where a run's time goes out as it advances: ROS 2's `/clock` (`ratelab_ros2::Bridge`),
/// or a count of it (ex13). Told each instant's run time just before the instant runs.
pub trait ClockOut {
    /// The run is about to run the instant at `t` (run time, ns).
    fn clock(&self, t: Nanos);
}

/// What [`DrivePolicy::intake`], [`DrivePolicy::ran`] and [`DrivePolicy::at_end`] ask of
/// the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Intake {
    /// Go on.
    Go,
    /// Run nothing now, and come back (through the stop flag) to intake. A policy that holds
    /// has waited for its controls (at most a few tens of ms), so the loop does not spin.
    Hold,
    /// Return [`Drove::Left`]; the run is not ended.
    Leave,
}

/// What [`DrivePolicy::pace`] asks before an instant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pace {
    /// Run it now.
    Now,
    /// Not yet: sleep this long (the loop caps it at [`MAX_PACING_SLEEP`]), then look again.
    Sleep(Duration),
}

/// An instant that ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Ran {
    /// Its run time.
    pub at: Nanos,
    /// The nodes that ticked, as bits (bit `i % 64` for node `i`, [`Step::Ran`]).
    pub ticked: u64,
}

/// How [`drive`] returned.
#[derive(Clone, Debug, PartialEq)]
pub enum Drove {
    /// The run ended (at its duration, a node stopped it or failed, or the stop flag).
    Ended(RunEnd),
    /// The policy left ([`Intake::Leave`]) with the run not ended.
    Left,
}

/// What a front end supplies to [`drive`]: its commands, its pace and what it tells after
/// each instant. Every method has a default, so a policy writes only what differs: the
/// headless run's is its [`Pacer`] when offered to ROS 2, and nothing ([`Unpaced`]) otherwise.
pub trait DrivePolicy {
    /// Between instants: take commands and controls (apply them with [`RunCore::apply`]).
    /// Called before every instant, and after a [`Intake::Hold`] or a pacing sleep.
    fn intake(&mut self, _core: &mut RunCore) -> Intake {
        Intake::Go
    }

    /// The next instant is at `t`: run it now, or sleep first.
    fn pace(&mut self, _t: Nanos) -> Pace {
        Pace::Now
    }

    /// The instant at `t` runs now: paced, made ready (it is where a scheduled phase
    /// change put it), just before `/clock` is told it. Called once per instant.
    fn starting(&mut self, _t: Nanos) {}

    /// An instant ran.
    fn ran(&mut self, _core: &mut RunCore, _ran: Ran) {}

    /// The run has ended (`end`): [`Intake::Leave`] (the default) returns
    /// [`Drove::Ended`]; [`Intake::Hold`] (and `Go`, the same here) keeps the ended run. It
    /// is asked again after each intake that returns `Go`, so a policy that holds an ended
    /// run should return `Hold` from `intake` (after waiting for its controls) until it
    /// leaves.
    fn at_end(&mut self, _core: &mut RunCore, _end: &RunEnd) -> Intake {
        Intake::Leave
    }
}

/// The policy with nothing to add: every instant as fast as it runs, no commands.
#[derive(Clone, Copy, Debug, Default)]
pub struct Unpaced;

impl DrivePolicy for Unpaced {}

/// Keeps pace with the wall clock at a speed: run time `anchor` is the wall instant the
/// pacer was anchored at, and run time passes `speed` times as fast as the wall's (`None`:
/// as fast as the instants run). The headless run offered to ROS 2 runs at ×1; the lab at
/// the speed its keys chose, anchored again when paused, resumed or sped up; a launch the
/// lab follows keeps its lockstep's horizon within the run time due
/// ([`Pacer::run_time_now`]).
#[derive(Clone, Copy, Debug)]
pub struct Pacer {
    anchor_run: Nanos,
    anchor_wall: Instant,
    speed: Option<f64>,
}

impl Pacer {
    /// Run time `at` is now on the wall; run time then passes at `speed` (× the wall's;
    /// `None`: no pacing). A speed that is not finite and positive paces nothing.
    pub fn new(at: Nanos, speed: Option<f64>) -> Pacer {
        Pacer {
            anchor_run: at,
            anchor_wall: Instant::now(),
            speed: speed.filter(|x| x.is_finite() && *x > 0.0),
        }
    }

    /// Anchor again: run time `at` is now (after a pause, a seek or a change of speed).
    pub fn anchor(&mut self, at: Nanos) {
        self.anchor_run = at;
        self.anchor_wall = Instant::now();
    }

    /// A new speed from run time `at`, now ([`Pacer::new`]'s rule).
    pub fn set_speed(&mut self, at: Nanos, speed: Option<f64>) {
        *self = Pacer::new(at, speed);
    }

    /// The wall instant at which run time `t` is due (`None`: unpaced).
    pub fn due(&self, t: Nanos) -> Option<Instant> {
        let x = self.speed?;
        let ahead_ns = t.saturating_sub(self.anchor_run).0 as f64 / x;
        Some(self.anchor_wall + Duration::from_nanos(ahead_ns as u64))
    }

    /// The run time due now: how far the wall clock has come since the anchor, at the
    /// speed (`None`: unpaced, nothing holds the run back).
    pub fn run_time_now(&self) -> Option<Nanos> {
        let x = self.speed?;
        let ahead_ns = self.anchor_wall.elapsed().as_secs_f64() * x * 1e9;
        Some(
            self.anchor_run
                .saturating_add(Nanos(ahead_ns.min(u64::MAX as f64) as u64)),
        )
    }

    /// Run `t` now when it is due, else sleep until it is (at most [`MAX_PACING_SLEEP`]).
    pub fn pace(&self, t: Nanos) -> Pace {
        match self.due(t) {
            Some(due) => match due.checked_duration_since(Instant::now()) {
                Some(wait) if !wait.is_zero() => Pace::Sleep(wait.min(MAX_PACING_SLEEP)),
                _ => Pace::Now,
            },
            None => Pace::Now,
        }
    }
}

impl DrivePolicy for Pacer {
    fn pace(&mut self, t: Nanos) -> Pace {
        Pacer::pace(self, t)
    }
}

/// Drive `core` under the virtual clock, instant by instant, with `policy` (module docs for
/// the order), until the run ends and the policy lets it go, or the policy leaves. `stop`
/// set ends the run as interrupted; `clock` is told each instant's time before it runs.
///
/// Generic over the policy, so the headless run's loop pays no dynamic call per instant.
pub fn drive<P: DrivePolicy + ?Sized>(
    core: &mut RunCore,
    policy: &mut P,
    stop: &StopFlag,
    clock: Option<&dyn ClockOut>,
) -> Drove {
    loop {
        if stop.is_stopped() {
            return Drove::Ended(core.interrupt());
        }
        match policy.intake(core) {
            Intake::Go => {}
            Intake::Hold => continue,
            Intake::Leave => return Drove::Left,
        }
        if let Some(end) = core.end().cloned() {
            match policy.at_end(core, &end) {
                Intake::Leave => return Drove::Ended(end),
                Intake::Go | Intake::Hold => continue,
            }
        }
        let Some(next) = core.next_instant() else {
            core.finish_at_duration();
            continue;
        };
        if let Pace::Sleep(wait) = policy.pace(next) {
            std::thread::sleep(wait.min(MAX_PACING_SLEEP));
            continue;
        }
        let Some(t) = core.prepare_instant() else {
            continue; // a phase change moved it past the duration: the end, next time round
        };
        if t != next {
            // Moved later by a scheduled phase change: waited for without intake (module docs).
            while let Pace::Sleep(wait) = policy.pace(t) {
                if stop.is_stopped() {
                    return Drove::Ended(core.interrupt());
                }
                std::thread::sleep(wait.min(MAX_PACING_SLEEP));
            }
        }
        policy.starting(t);
        if let Some(out) = clock {
            out.clock(t);
        }
        if let Step::Ran { at, ticked } = core.run_prepared(t) {
            policy.ran(core, Ran { at, ticked });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{Command, TimedCommand};
    use crate::config::RunConfig;
    use crate::runcore::CoreOptions;
    use crate::scheduler::EndReason;
    use std::cell::RefCell;

    fn core(cfg: &RunConfig, commands: Vec<TimedCommand>) -> RunCore {
        let opts = CoreOptions {
            keep_trace: true,
            commands,
            history_every: Some(Nanos(100_000_000)),
            ..CoreOptions::default()
        };
        RunCore::new(cfg, Box::new(crate::policy::Scripted), opts).unwrap()
    }

    fn secs(s: f64) -> Nanos {
        Nanos((s * 1e9).round() as u64)
    }

    fn chapter(duration_s: f64) -> RunConfig {
        RunConfig {
            duration: secs(duration_s),
            ..RunConfig::default()
        }
    }

    /// Records the instants `/clock` is told.
    #[derive(Default)]
    struct Clocks(RefCell<Vec<Nanos>>);
    impl ClockOut for Clocks {
        fn clock(&self, t: Nanos) {
            self.0.borrow_mut().push(t);
        }
    }

    /// Records the instants that ran, and applies a command after the `at`-th.
    #[derive(Default)]
    struct Script {
        ran: Vec<Nanos>,
        apply_after: Option<(usize, Command)>,
        intakes: usize,
    }
    impl DrivePolicy for Script {
        fn intake(&mut self, core: &mut RunCore) -> Intake {
            self.intakes += 1;
            if let Some((n, _)) = &self.apply_after {
                if *n == self.ran.len() {
                    let (_, c) = self.apply_after.take().unwrap();
                    core.apply(c).unwrap();
                }
            }
            Intake::Go
        }
        fn ran(&mut self, _core: &mut RunCore, ran: Ran) {
            self.ran.push(ran.at);
        }
    }

    fn stepped_to_end(mut c: RunCore) -> (RunEnd, String, Vec<TimedCommand>) {
        let end = loop {
            if let Step::Ended(end) = c.step() {
                break end;
            }
        };
        (end, format!("{:?}", c.metrics()), c.applied().to_vec())
    }

    #[test]
    fn a_driven_run_is_the_stepped_run_and_clock_is_told_each_instant_that_ran() {
        let cfg = chapter(1.0);
        let (end, metrics, _) = stepped_to_end(core(&cfg, vec![]));
        let mut c = core(&cfg, vec![]);
        let clocks = Clocks::default();
        let mut script = Script::default();
        let drove = drive(&mut c, &mut script, &StopFlag::new(), Some(&clocks));
        assert_eq!(drove, Drove::Ended(end.clone()));
        assert_eq!(end.reason, EndReason::Duration);
        assert_eq!(format!("{:?}", c.metrics()), metrics);
        assert_eq!(
            *clocks.0.borrow(),
            script.ran,
            "/clock: each instant that ran, in order"
        );
        assert!(script.ran.windows(2).all(|w| w[0] < w[1]));
        assert!(
            script.intakes > script.ran.len(),
            "intake before every instant"
        );
    }

    #[test]
    fn a_command_taken_between_instants_is_logged_at_the_next_before_its_scheduled_ones() {
        let cfg = chapter(1.0);
        // The instants of the run, to schedule a command on the 41st.
        let mut plain = Script::default();
        drive(&mut core(&cfg, vec![]), &mut plain, &StopFlag::new(), None);
        let scheduled = TimedCommand {
            at_ns: plain.ran[40].0,
            command: Command::SetSensorHz { hz: 40.0 },
        };
        let mut c = core(&cfg, vec![scheduled.clone()]);
        let mut script = Script {
            apply_after: Some((40, Command::SetControlHz { hz: 25.0 })),
            ..Script::default()
        };
        drive(&mut c, &mut script, &StopFlag::new(), None);
        let applied = c.applied().to_vec();
        assert_eq!(applied.len(), 2);
        assert_eq!(script.ran[40], plain.ran[40]);
        // Taken before the instant was made ready: logged at it, before the scheduled one,
        // the order a seek and a replay apply them in.
        assert_eq!(Nanos(applied[0].at_ns), script.ran[40]);
        assert_eq!(applied[0].command, Command::SetControlHz { hz: 25.0 });
        assert_eq!(applied[1], scheduled);
        let driven = format!("{:?}", c.metrics());
        // The same command, scheduled: the same run.
        let (_, replayed, _) = stepped_to_end(core(&cfg, applied));
        assert_eq!(driven, replayed);
    }

    #[test]
    fn clock_is_told_the_instant_a_scheduled_phase_change_moved_to_not_the_one_it_left() {
        let cfg = chapter(1.0);
        // Every node's ticks moved 7 ms off their grid from 0.5 s: the instant at 0.5 s no
        // longer runs.
        let names: Vec<String> = cfg.graph.nodes.iter().map(|n| n.name.clone()).collect();
        let commands: Vec<TimedCommand> = names
            .iter()
            .map(|node| TimedCommand {
                at_ns: 500_000_000,
                command: Command::SetPhase {
                    node: node.clone(),
                    phase_ms: 7.0,
                },
            })
            .collect();
        let mut c = core(&cfg, commands.clone());
        let clocks = Clocks::default();
        let mut script = Script::default();
        drive(&mut c, &mut script, &StopFlag::new(), Some(&clocks));
        assert_eq!(*clocks.0.borrow(), script.ran);
        assert!(!script.ran.contains(&Nanos(500_000_000)));
        let (_, stepped, _) = stepped_to_end(core(&cfg, commands));
        assert_eq!(format!("{:?}", c.metrics()), stepped);
    }

    /// Sleeps once before the instant `moved`, counting the intakes until it has run.
    struct WaitAtMoved {
        moved: Nanos,
        slept: bool,
        ran_moved: bool,
        intakes_while_waiting: usize,
    }
    impl DrivePolicy for WaitAtMoved {
        fn intake(&mut self, _core: &mut RunCore) -> Intake {
            if self.slept && !self.ran_moved {
                self.intakes_while_waiting += 1;
            }
            Intake::Go
        }
        fn pace(&mut self, t: Nanos) -> Pace {
            if t == self.moved && !self.slept {
                self.slept = true;
                return Pace::Sleep(Duration::from_millis(1));
            }
            Pace::Now
        }
        fn ran(&mut self, _core: &mut RunCore, ran: Ran) {
            self.ran_moved |= ran.at == self.moved;
        }
    }

    #[test]
    fn an_instant_a_phase_change_moved_is_waited_for_without_intake() {
        let cfg = chapter(1.0);
        let commands: Vec<TimedCommand> = (cfg.graph.nodes.iter())
            .map(|n| TimedCommand {
                at_ns: 500_000_000,
                command: Command::SetPhase {
                    node: n.name.clone(),
                    phase_ms: 7.0,
                },
            })
            .collect();
        let mut p = WaitAtMoved {
            moved: Nanos(507_000_000),
            slept: false,
            ran_moved: false,
            intakes_while_waiting: 0,
        };
        drive(&mut core(&cfg, commands), &mut p, &StopFlag::new(), None);
        assert!(
            p.slept && p.ran_moved,
            "the instant moved to 507 ms, and ran"
        );
        assert_eq!(p.intakes_while_waiting, 0);
    }

    /// Stops after `n` instants; holds once the run has ended.
    struct StopAfter {
        n: usize,
        ran: usize,
        stop: StopFlag,
        leave: bool,
    }
    impl DrivePolicy for StopAfter {
        fn intake(&mut self, _core: &mut RunCore) -> Intake {
            if self.leave && self.ran == self.n {
                Intake::Leave
            } else {
                Intake::Go
            }
        }
        fn ran(&mut self, _core: &mut RunCore, _ran: Ran) {
            self.ran += 1;
            if !self.leave && self.ran == self.n {
                self.stop.stop();
            }
        }
    }

    #[test]
    fn a_stop_interrupts_the_run_and_leaving_does_not() {
        let cfg = chapter(1.0);
        let stop = StopFlag::new();
        let mut c = core(&cfg, vec![]);
        let mut p = StopAfter {
            n: 10,
            ran: 0,
            stop: stop.clone(),
            leave: false,
        };
        let Drove::Ended(end) = drive(&mut c, &mut p, &stop, None) else {
            panic!("a stop ends the run")
        };
        assert_eq!(end.reason, EndReason::Interrupted);
        assert_eq!(end.at, c.now());
        assert_eq!(p.ran, 10);

        let mut c = core(&cfg, vec![]);
        let mut p = StopAfter {
            n: 10,
            ran: 0,
            stop: StopFlag::new(),
            leave: true,
        };
        assert_eq!(drive(&mut c, &mut p, &StopFlag::new(), None), Drove::Left);
        assert!(
            c.end().is_none(),
            "left, not ended: the run goes on from here"
        );
        p.leave = false;
        let Drove::Ended(end) = drive(&mut c, &mut p, &StopFlag::new(), None) else {
            unreachable!()
        };
        assert_eq!(end.reason, EndReason::Duration);
        let (stepped, metrics, _) = stepped_to_end(core(&cfg, vec![]));
        assert_eq!(end, stepped);
        assert_eq!(format!("{:?}", c.metrics()), metrics);
    }

    /// Holds the ended run once, seeks back into it, and lets it end again.
    struct HoldThenSeek {
        ends: Vec<RunEnd>,
        back_to: Nanos,
    }
    impl DrivePolicy for HoldThenSeek {
        fn at_end(&mut self, core: &mut RunCore, end: &RunEnd) -> Intake {
            self.ends.push(end.clone());
            if self.ends.len() == 1 {
                core.seek(self.back_to).unwrap();
                Intake::Hold
            } else {
                Intake::Leave
            }
        }
    }

    #[test]
    fn an_ended_run_held_and_sought_back_runs_on_to_the_same_end() {
        let cfg = chapter(0.6);
        let mut c = core(&cfg, vec![]);
        let mut p = HoldThenSeek {
            ends: vec![],
            back_to: secs(0.2),
        };
        let drove = drive(&mut c, &mut p, &StopFlag::new(), None);
        assert_eq!(p.ends.len(), 2);
        assert_eq!(drove, Drove::Ended(p.ends[0].clone()));
        let (_, metrics, _) = stepped_to_end(core(&cfg, vec![]));
        assert_eq!(format!("{:?}", c.metrics()), metrics);
    }

    #[test]
    fn the_pacer_runs_what_is_due_and_sleeps_at_most_the_cap_for_the_rest() {
        let p = Pacer::new(secs(1.0), Some(2.0));
        assert_eq!(p.pace(secs(0.5)), Pace::Now, "behind: now");
        assert_eq!(p.pace(secs(1.0)), Pace::Now);
        match p.pace(secs(1.004)) {
            Pace::Sleep(d) => assert!(d <= Duration::from_millis(2), "4 ms at ×2 is 2 ms: {d:?}"),
            Pace::Now => panic!("not yet due"),
        }
        assert_eq!(p.pace(secs(60.0)), Pace::Sleep(MAX_PACING_SLEEP));
        let now = p.run_time_now().unwrap();
        assert!(now >= secs(1.0) && now < secs(3.0), "{now:?}");
        assert_eq!(Pacer::new(Nanos::ZERO, None).run_time_now(), None);
        let due = p.due(secs(3.0)).unwrap();
        let ahead = due.duration_since(p.anchor_wall);
        assert_eq!(ahead, Duration::from_secs(1), "2 s of run time at ×2");
        for speed in [
            None,
            Some(0.0),
            Some(-1.0),
            Some(f64::NAN),
            Some(f64::INFINITY),
        ] {
            let p = Pacer::new(Nanos::ZERO, speed);
            assert_eq!(p.pace(secs(1e6)), Pace::Now, "{speed:?}");
        }
    }
}
