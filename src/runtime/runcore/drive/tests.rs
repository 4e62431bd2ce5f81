//! The drive loop's tests: instant by instant (a driven run is the stepped run; commands
//! between instants, a phase change, a stop, leaving, an ended run held) and event by event
//! (run here or from reports, across waits; the limit, an error, an end).

mod instants {
    use super::super::*;
    use crate::command::{Command, TimedCommand};
    use crate::config::RunConfig;
    use crate::runcore::CoreOptions;
    use crate::runcore::{RunCore, Step};
    use crate::scheduler::EndReason;
    use std::cell::RefCell;
    use std::convert::Infallible;

    fn core(cfg: &RunConfig, commands: Vec<TimedCommand>) -> RunCore {
        let opts = CoreOptions {
            keep_trace: true,
            commands,
            history_every: Some(Nanos(100_000_000)),
            ..CoreOptions::default()
        };
        RunCore::new(cfg, Box::new(crate::policy::Scripted), opts).unwrap()
    }

    /// [`drive`] instant by instant from the start, `stop` and `clock` as given.
    fn instants<P: DrivePolicy<Nanos, RunCore, Error = Infallible>>(
        c: &mut RunCore,
        p: &mut P,
        stop: &StopFlag,
        clock: Option<&dyn ClockOut>,
    ) -> Drove {
        let Ok(drove) = drive(c, &mut Cursor::default(), p, Some(stop), clock);
        drove
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
    impl DrivePolicy<Nanos, RunCore> for Script {
        type Error = Infallible;
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
        fn taken(
            &mut self,
            _core: &mut RunCore,
            _index: u64,
            at: Nanos,
            _ticked: u64,
        ) -> Result<Turn, Infallible> {
            self.ran.push(at);
            Ok(Turn::Go)
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
        let drove = instants(&mut c, &mut script, &StopFlag::new(), Some(&clocks));
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
        instants(&mut core(&cfg, vec![]), &mut plain, &StopFlag::new(), None);
        let scheduled = TimedCommand {
            at_ns: plain.ran[40].0,
            command: Command::SetSensorHz { hz: 40.0 },
        };
        let mut c = core(&cfg, vec![scheduled.clone()]);
        let mut script = Script {
            apply_after: Some((40, Command::SetControlHz { hz: 25.0 })),
            ..Script::default()
        };
        instants(&mut c, &mut script, &StopFlag::new(), None);
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

    /// Counts the intakes that find nothing left to run and the run not yet ended.
    #[derive(Default)]
    struct AtTheEdge {
        intakes: usize,
    }
    impl DrivePolicy<Nanos, RunCore> for AtTheEdge {
        type Error = Infallible;
        fn intake(&mut self, core: &mut RunCore) -> Intake {
            if core.next_instant().is_none() && core.end().is_none() {
                self.intakes += 1;
            }
            Intake::Go
        }
    }

    #[test]
    fn an_instant_moved_past_the_duration_ends_the_run_after_one_more_intake() {
        let cfg = chapter(1.0);
        // The last instant (1 s) moved 7 ms past the duration by a phase change at it.
        let commands: Vec<TimedCommand> = (cfg.graph.nodes.iter())
            .map(|n| TimedCommand {
                at_ns: 1_000_000_000,
                command: Command::SetPhase {
                    node: n.name.clone(),
                    phase_ms: 7.0,
                },
            })
            .collect();
        let mut p = AtTheEdge::default();
        let mut c = core(&cfg, commands.clone());
        let drove = instants(&mut c, &mut p, &StopFlag::new(), None);
        let Drove::Ended(end) = drove else {
            panic!("{drove:?}")
        };
        assert_eq!(
            (end.reason.clone(), end.at),
            (EndReason::Duration, cfg.duration)
        );
        assert!(c.now() < cfg.duration, "the instant at 1 s did not run");
        // Between the move and the end, one intake (a stop or a command is still taken
        // there, as before the end at any other instant).
        assert_eq!(p.intakes, 1);
        let (stepped, metrics, _) = stepped_to_end(core(&cfg, commands));
        assert_eq!((end, format!("{:?}", c.metrics())), (stepped, metrics));
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
        instants(&mut c, &mut script, &StopFlag::new(), Some(&clocks));
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
    impl DrivePolicy<Nanos, RunCore> for WaitAtMoved {
        type Error = Infallible;
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
        fn taken(
            &mut self,
            _core: &mut RunCore,
            _index: u64,
            at: Nanos,
            _ticked: u64,
        ) -> Result<Turn, Infallible> {
            self.ran_moved |= at == self.moved;
            Ok(Turn::Go)
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
        instants(&mut core(&cfg, commands), &mut p, &StopFlag::new(), None);
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
    impl DrivePolicy<Nanos, RunCore> for StopAfter {
        type Error = Infallible;
        fn intake(&mut self, _core: &mut RunCore) -> Intake {
            if self.leave && self.ran == self.n {
                Intake::Leave
            } else {
                Intake::Go
            }
        }
        fn taken(
            &mut self,
            _core: &mut RunCore,
            _index: u64,
            _at: Nanos,
            _ticked: u64,
        ) -> Result<Turn, Infallible> {
            self.ran += 1;
            if !self.leave && self.ran == self.n {
                self.stop.stop();
            }
            Ok(Turn::Go)
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
        let Drove::Ended(end) = instants(&mut c, &mut p, &stop, None) else {
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
        assert_eq!(
            instants(&mut c, &mut p, &StopFlag::new(), None),
            Drove::Left
        );
        assert!(
            c.end().is_none(),
            "left, not ended: the run goes on from here"
        );
        p.leave = false;
        let Drove::Ended(end) = instants(&mut c, &mut p, &StopFlag::new(), None) else {
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
    impl DrivePolicy<Nanos, RunCore> for HoldThenSeek {
        type Error = Infallible;
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
        let drove = instants(&mut c, &mut p, &StopFlag::new(), None);
        assert_eq!(p.ends.len(), 2);
        assert_eq!(drove, Drove::Ended(p.ends[0].clone()));
        let (_, metrics, _) = stepped_to_end(core(&cfg, vec![]));
        assert_eq!(format!("{:?}", c.metrics()), metrics);
    }
}

mod events {
    use super::super::*;
    use crate::config::RunConfig;
    use crate::runcore::CoreOptions;
    use crate::runcore::{Follower, RunCore, Step};
    use crate::scheduler::EndReason;
    use ratelab_core::node::Flow;

    fn core(cfg: &RunConfig) -> RunCore {
        let opts = CoreOptions {
            keep_trace: true,
            ..CoreOptions::default()
        };
        RunCore::new(cfg, Box::new(crate::policy::Scripted), opts).unwrap()
    }

    /// [`drive`] event by event, no `/clock`.
    fn take_events<C, P>(
        course: &mut C,
        cursor: &mut Cursor<Event>,
        p: &mut P,
        stop: Option<&StopFlag>,
    ) -> Result<Drove, P::Error>
    where
        C: Course<Event>,
        P: DrivePolicy<Event, C>,
    {
        drive(course, cursor, p, stop, None)
    }

    /// Takes an event as run in another process (both courses that draw events).
    trait Elsewhere {
        fn elsewhere(&mut self, event: Event, compute: Nanos);
    }
    impl Elsewhere for Events<'_> {
        fn elsewhere(&mut self, event: Event, compute: Nanos) {
            self.ran_elsewhere(event, compute);
        }
    }
    impl Elsewhere for Follower {
        fn elsewhere(&mut self, event: Event, compute: Nanos) {
            self.ran_elsewhere(event, compute);
        }
    }

    fn chapter() -> RunConfig {
        RunConfig {
            duration: Nanos(400_000_000),
            ..RunConfig::default()
        }
    }

    fn stepped_metrics(cfg: &RunConfig) -> String {
        let mut c = core(cfg);
        while let Step::Ran { .. } = c.step() {}
        format!("{:?}", c.metrics())
    }

    /// Runs every event here; waits every `wait_every` events, once.
    struct Here {
        wait_every: Option<u64>,
        waited_at: Vec<u64>,
        taken: Vec<(u64, Event)>,
    }
    impl<'c> DrivePolicy<Event, Events<'c>> for Here {
        type Error = EndReason;
        fn turn(&mut self, index: u64, _event: Event) -> Result<Turn, EndReason> {
            match self.wait_every {
                Some(n) if index % n == 0 && !self.waited_at.contains(&index) => {
                    self.waited_at.push(index);
                    Ok(Turn::Wait)
                }
                _ => Ok(Turn::Go),
            }
        }
        fn take(
            &mut self,
            core: &mut Events<'c>,
            _: u64,
            event: Event,
        ) -> Result<Taken, EndReason> {
            let (flow, _) = core.run_event(event)?;
            Ok(Taken::Ran {
                over: flow == Flow::Stop,
                ticked: 0,
            })
        }
        fn taken(
            &mut self,
            _core: &mut Events<'c>,
            index: u64,
            event: Event,
            _ticked: u64,
        ) -> Result<Turn, EndReason> {
            self.taken.push((index, event));
            Ok(Turn::Go)
        }
    }

    #[test]
    fn events_taken_here_across_waits_are_the_stepped_run() {
        let cfg = chapter();
        let mut c = core(&cfg);
        let mut cursor = Cursor::default();
        let mut p = Here {
            wait_every: Some(7),
            waited_at: vec![],
            taken: vec![],
        };
        let mut calls = 0;
        let drew = loop {
            calls += 1;
            match take_events(&mut Events(&mut c), &mut cursor, &mut p, None).unwrap() {
                Drove::Waiting => continue,
                other => break other,
            }
        };
        assert_eq!(drew, Drove::Exhausted);
        assert!(calls > 1 && p.waited_at.len() == calls - 1);
        let indices: Vec<u64> = p.taken.iter().map(|(i, _)| *i).collect();
        assert_eq!(indices, (0..cursor.index()).collect::<Vec<_>>());
        // Every event taken once, in order, whatever the waits between.
        c.finish_at_duration();
        assert_eq!(format!("{:?}", c.metrics()), stepped_metrics(&cfg));
    }

    /// Records, per instant, the nodes that ticked in it as the loop tells them.
    #[derive(Default)]
    struct Ticks(Vec<(Nanos, u64)>);
    impl<U: Unit, C: Course<U>> DrivePolicy<U, C> for Ticks {
        type Error = std::convert::Infallible;
        fn taken(&mut self, _: &mut C, _: u64, unit: U, ticked: u64) -> Result<Turn, Self::Error> {
            match self.0.last_mut() {
                Some((t, bits)) if *t == unit.at() => *bits |= ticked,
                _ => self.0.push((unit.at(), ticked)),
            }
            Ok(Turn::Go)
        }
    }

    #[test]
    fn events_run_here_by_default_tick_the_nodes_each_instant_ticks() {
        let cfg = chapter();
        let mut by_instant = Ticks::default();
        let mut c = core(&cfg);
        let mut cursor = Cursor::<Nanos>::default();
        let drove = drive(&mut c, &mut cursor, &mut by_instant, None, None);
        assert!(matches!(drove, Ok(Drove::Ended(_))));
        let mut by_event = Ticks::default();
        let mut e = core(&cfg);
        let drove = take_events(
            &mut Events(&mut e),
            &mut Cursor::default(),
            &mut by_event,
            None,
        );
        assert_eq!(drove, Ok(Drove::Exhausted), "its end is the caller's");
        assert!(e.end().is_none());
        // An instant where only held outputs went out ticks no node.
        let started: Vec<(Nanos, u64)> = by_event.0.into_iter().filter(|x| x.1 != 0).collect();
        let ticked: Vec<(Nanos, u64)> = by_instant.0.into_iter().filter(|x| x.1 != 0).collect();
        assert!(ticked.len() > 10);
        assert_eq!(started, ticked);
        e.finish_at_duration();
        assert_eq!(format!("{:?}", e.metrics()), stepped_metrics(&cfg));
    }

    #[test]
    fn an_event_run_here_that_ends_the_run_ends_the_loop_as_the_instants_do() {
        // A 2 Hz policy lets the pole fall: the actuator's tick stops the run.
        let mut cfg = chapter();
        cfg.duration = Nanos(10_000_000_000);
        cfg.set_control_hz(2.0).unwrap();
        let mut by_instant = core(&cfg);
        let Ok(drove) = drive(
            &mut by_instant,
            &mut Cursor::<Nanos>::default(),
            &mut Unpaced,
            None,
            None,
        );
        let Drove::Ended(end) = drove else {
            panic!("{drove:?}")
        };
        assert_eq!(end.reason, EndReason::NodeStopped);
        let mut by_event = core(&cfg);
        let mut cursor = Cursor::default();
        let drove = take_events(&mut Events(&mut by_event), &mut cursor, &mut Unpaced, None);
        assert_eq!(
            drove,
            Ok(Drove::Ended(end.clone())),
            "the core knows its end"
        );
        assert_eq!(by_event.end(), Some(&end));
        assert_eq!(
            format!("{:?}", by_event.metrics()),
            format!("{:?}", by_instant.metrics())
        );
        // Called again, it draws nothing: the run has ended.
        let drove = take_events(&mut Events(&mut by_event), &mut cursor, &mut Unpaced, None);
        assert_eq!(drove, Ok(Drove::Ended(end)));
    }

    /// Records the times `/clock` is told.
    #[derive(Default)]
    struct Clocks(std::cell::RefCell<Vec<Nanos>>);
    impl ClockOut for Clocks {
        fn clock(&self, t: Nanos) {
            self.0.borrow_mut().push(t);
        }
    }

    #[test]
    fn clock_is_told_each_event_once_however_often_it_is_not_yet_here() {
        let cfg = chapter();
        let mut here = core(&cfg);
        let mut compute = vec![];
        let mut times = vec![];
        while let Some(e) = here.next_event() {
            compute.push(here.run_event(e).unwrap().1);
            times.push(e.at());
        }
        let mut c = core(&cfg);
        let mut cursor = Cursor::default();
        let mut p = Reports {
            compute,
            late: vec![0, 3, 3, 40],
            took: vec![],
        };
        let clocks = Clocks::default();
        let mut waits = 0;
        loop {
            match drive(
                &mut Events(&mut c),
                &mut cursor,
                &mut p,
                None,
                Some(&clocks),
            ) {
                Ok(Drove::Waiting) => waits += 1,
                other => {
                    assert_eq!(other, Ok(Drove::Exhausted));
                    break;
                }
            }
        }
        assert_eq!(waits, 4);
        assert_eq!(*clocks.0.borrow(), times);
    }

    /// Takes each event as run elsewhere, from a script of compute times; not yet for the
    /// events at `late` the first time they are asked.
    struct Reports {
        compute: Vec<Nanos>,
        late: Vec<u64>,
        took: Vec<Event>,
    }
    impl<O: Course<Event> + Elsewhere> DrivePolicy<Event, O> for Reports {
        type Error = String;
        fn take(&mut self, order: &mut O, index: u64, event: Event) -> Result<Taken, String> {
            if let Some(k) = self.late.iter().position(|&i| i == index) {
                self.late.remove(k);
                return Ok(Taken::NotYet);
            }
            let compute = *self.compute.get(index as usize).ok_or("no report")?;
            order.elsewhere(event, compute);
            self.took.push(event);
            Ok(Taken::Ran {
                over: false,
                ticked: 0,
            })
        }
    }

    #[test]
    fn a_follower_and_a_core_taking_reports_draw_the_same_order_and_stop_at_the_limit() {
        let cfg = chapter();
        // The compute times of the run's events, run here.
        let mut here = core(&cfg);
        let mut compute = vec![];
        let mut events = vec![];
        while let Some(e) = here.next_event() {
            compute.push(here.run_event(e).unwrap().1);
            events.push(e);
        }
        let n = events.len() as u64;
        let mut follower = Follower::new(&cfg).unwrap();
        let mut cursor = Cursor::default();
        let mut p = Reports {
            compute: compute.clone(),
            late: vec![3, 40],
            took: vec![],
        };
        let mut waits = 0;
        let drew = loop {
            match take_events(&mut follower, &mut cursor, &mut p, None) {
                Ok(Drove::Waiting) => {
                    waits += 1;
                    // The event not yet taken is kept, not drawn again.
                    assert_eq!(cursor.next(), Some(events[cursor.index() as usize]));
                }
                other => break other,
            }
        };
        assert_eq!((drew, waits, cursor.index()), (Ok(Drove::Exhausted), 2, n));
        assert_eq!(
            p.took, events,
            "the follower's order is the run's, event for event"
        );

        let mut elsewhere = core(&cfg);
        let mut cursor = Cursor {
            limit: Some(n / 2),
            ..Cursor::default()
        };
        let mut p = Reports {
            compute,
            late: vec![],
            took: vec![],
        };
        let drew = take_events(&mut Events(&mut elsewhere), &mut cursor, &mut p, None);
        assert_eq!(
            (drew, cursor.index(), cursor.left()),
            (Ok(Drove::Limit), n / 2, 0)
        );
        assert_eq!(cursor.next(), None, "nothing drawn at the limit");
        cursor.limit = Some(n);
        assert_eq!(cursor.left(), n - n / 2);
        // Goes on from the limit, at the event after the last taken.
        let drew = take_events(&mut Events(&mut elsewhere), &mut cursor, &mut p, None);
        assert_eq!((drew, cursor.index()), (Ok(Drove::Limit), n));
        assert_eq!(p.took, events);
        // Run elsewhere, the executors' figures are the run here.
        assert_eq!(
            format!("{:?}", elsewhere.scheduler().figures(cfg.duration)),
            format!("{:?}", here.scheduler().figures(cfg.duration))
        );
    }

    #[test]
    fn an_error_leaves_the_cursor_on_its_event_and_a_stop_is_seen_first() {
        let cfg = chapter();
        let mut c = core(&cfg);
        let mut cursor = Cursor::default();
        let mut p = Reports {
            compute: vec![Nanos::ZERO; 5],
            late: vec![],
            took: vec![],
        };
        let drew = take_events(&mut Events(&mut c), &mut cursor, &mut p, None);
        assert_eq!(drew, Err("no report".to_string()));
        assert_eq!(cursor.index(), 5);
        assert!(cursor.next().is_some(), "the event that failed is kept");
        let stop = StopFlag::new();
        stop.stop();
        let drew = take_events(&mut Events(&mut c), &mut cursor, &mut p, Some(&stop));
        assert_eq!((drew, cursor.index()), (Ok(Drove::Stopped), 5));
    }

    /// Runs every event here; the event at `hold` ends the run when `over`, and after
    /// taking it the policy asks to wait (samples held back) when `wait`.
    struct HoldAfter {
        hold: u64,
        over: bool,
        wait: bool,
    }
    impl<'c> DrivePolicy<Event, Events<'c>> for HoldAfter {
        type Error = EndReason;
        fn take(
            &mut self,
            core: &mut Events<'c>,
            index: u64,
            event: Event,
        ) -> Result<Taken, EndReason> {
            core.run_event(event)?;
            Ok(Taken::Ran {
                over: self.over && index == self.hold,
                ticked: 0,
            })
        }
        fn taken(
            &mut self,
            _core: &mut Events<'c>,
            index: u64,
            _event: Event,
            _ticked: u64,
        ) -> Result<Turn, EndReason> {
            Ok(if self.wait && index == self.hold {
                Turn::Wait
            } else {
                Turn::Go
            })
        }
    }

    #[test]
    fn an_event_that_ends_the_run_is_taken_and_ends_the_loop() {
        let cfg = chapter();
        let mut c = core(&cfg);
        let mut cursor = Cursor::default();
        let mut p = HoldAfter {
            hold: 9,
            over: true,
            wait: false,
        };
        let drew = take_events(&mut Events(&mut c), &mut cursor, &mut p, None);
        assert_eq!((drew, cursor.index()), (Ok(Drove::Over), 10));
    }

    #[test]
    fn a_wait_after_an_event_returns_past_it_and_an_end_there_is_the_end() {
        let cfg = chapter();
        let mut c = core(&cfg);
        let mut cursor = Cursor::default();
        let mut p = HoldAfter {
            hold: 4,
            over: false,
            wait: true,
        };
        let drew = take_events(&mut Events(&mut c), &mut cursor, &mut p, None);
        assert_eq!(
            (drew, cursor.index(), cursor.next()),
            (Ok(Drove::Waiting), 5, None)
        );
        p.hold = u64::MAX;
        let drew = take_events(&mut Events(&mut c), &mut cursor, &mut p, None);
        assert_eq!(drew, Ok(Drove::Exhausted), "on from the event after it");

        let mut c = core(&cfg);
        let mut cursor = Cursor::default();
        let mut p = HoldAfter {
            hold: 4,
            over: true,
            wait: true,
        };
        let drew = take_events(&mut Events(&mut c), &mut cursor, &mut p, None);
        assert_eq!((drew, cursor.index()), (Ok(Drove::Over), 5));
    }
}
