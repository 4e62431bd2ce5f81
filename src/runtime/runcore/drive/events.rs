//! The drive loop's event mode: a run across processes under the virtual clock, drawn one
//! event at a time ([`RunCore::next_event`]) because each event's node runs in one process
//! and the others take it from its report. A process's lockstep
//! (`ratelab_distributed::process`, its core an [`EventOrder`]) and the launcher that
//! follows the processes (a [`Follower`]) both go through [`drive_events`]; an
//! [`EventPolicy`] supplies only the event source: whether an event's turn has come (the
//! launcher's horizon, which thread may run it), and how it is taken (run here, or its
//! report).
//!
//! The loop never blocks and never sleeps: it runs on Zenoh's receive thread as well as on
//! a main thread, so where an event's input is not here yet it returns
//! [`Drew::Waiting`] and is called again when something comes in, the [`Cursor`] keeping
//! its place.
//!
//! # The order around an event
//! 1. The stop flag: set, [`Drew::Stopped`] (what a stop means is the caller's: a process's
//!    error, the launcher's grace period).
//! 2. The limit ([`Cursor::limit`]): the run's count of events, once known; none at or past
//!    it is taken ([`Drew::Limit`]).
//! 3. The event drawn (or kept from last time, until it is taken): none left is the run's
//!    duration reached ([`Drew::Exhausted`]).
//! 4. [`EventPolicy::turn`]: `Wait` returns [`Drew::Waiting`].
//! 5. [`EventPolicy::take`]: run here or from its report, or not yet
//!    ([`Drew::Waiting`]); an error from `turn` or `take` ends the loop with the cursor
//!    still on the event.
//! 6. The cursor moves on, [`EventPolicy::taken`] is told, and an event that stopped the run
//!    or failed ends it ([`Drew::Over`]).
//!
//! Taken in this order, the events are the one process's run, byte for byte: the same
//! scheduler, the same instants and ties, each start's compute time as the process that
//! ran it reports it (tests below; `tests/it/distributed.rs` across processes).

use super::super::{Follower, RunCore};
use crate::scheduler::{Event, StopFlag};
use ratelab_core::time::Nanos;

/// A run's one order of events, as [`drive_events`] draws it: the run core's (a process
/// runs its own nodes' events) or a [`Follower`]'s (the launcher, which runs none).
pub trait EventOrder {
    /// The next event, the clock moved on to it; `None` past the run's end or duration
    /// ([`RunCore::next_event`]).
    fn next_event(&mut self) -> Option<Event>;
    /// `event` ran in another process, a start's tick computing for `compute` there
    /// ([`RunCore::ran_elsewhere`]).
    fn ran_elsewhere(&mut self, event: Event, compute: Nanos);
}

impl EventOrder for RunCore {
    fn next_event(&mut self) -> Option<Event> {
        RunCore::next_event(self)
    }
    fn ran_elsewhere(&mut self, event: Event, compute: Nanos) {
        RunCore::ran_elsewhere(self, event, compute);
    }
}

impl EventOrder for Follower {
    fn next_event(&mut self) -> Option<Event> {
        Follower::next_event(self)
    }
    fn ran_elsewhere(&mut self, event: Event, compute: Nanos) {
        Follower::ran_elsewhere(self, event, compute);
    }
}

/// Where a run drawn event by event stands between calls of [`drive_events`]: the next
/// event's place in the run's order, the event once drawn and until it is taken, and the
/// run's count of events once it is known.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Cursor {
    index: u64,
    next: Option<Event>,
    /// The run's events, once known (the launcher's word at a run's end): none at or past
    /// this index is taken.
    pub limit: Option<u64>,
}

impl Cursor {
    /// A cursor at the run's `index`-th event, none drawn: where a run whose first `index`
    /// events were taken stands.
    pub fn at(index: u64) -> Cursor {
        Cursor {
            index,
            ..Cursor::default()
        }
    }

    /// The next event's place in the run's order (0-based): the events taken so far.
    pub fn index(&self) -> u64 {
        self.index
    }

    /// The next event, once drawn and until it is taken.
    pub fn next(&self) -> Option<Event> {
        self.next
    }

    /// Events still to take before the limit (0 without one).
    pub fn left(&self) -> u64 {
        self.limit.map_or(0, |l| l.saturating_sub(self.index))
    }
}

/// What [`EventPolicy::turn`] and [`EventPolicy::taken`] ask of the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Turn {
    /// Go on.
    Go,
    /// Return [`Drew::Waiting`]; the caller calls again when what it waits for comes.
    Wait,
}

/// How [`EventPolicy::take`] took an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Taken {
    /// Taken (run here, or from its report); `over`: its node stopped the run or failed.
    Ran {
        /// The run ends with this event.
        over: bool,
    },
    /// Not yet: an input it must see, or its report, is still on its way.
    NotYet,
}

/// How [`drive_events`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Drew {
    /// Waiting: for the policy's turn, an input or a report. Call again when it comes.
    Waiting,
    /// The event just taken stopped the run or failed.
    Over,
    /// No event left: the run reached its duration (or its core had ended).
    Exhausted,
    /// Every event up to [`Cursor::limit`] is taken.
    Limit,
    /// The stop flag was set.
    Stopped,
}

/// A run's event source (module docs): when an event's turn comes and how it is taken.
pub trait EventPolicy<O: EventOrder + ?Sized> {
    /// Why the run cannot go on (a report out of step, a report that cannot be sent).
    type Error;

    /// The event at `index`, `event`, is next: take it now, or wait (past the horizon; or
    /// on a thread that may not run it).
    fn turn(&mut self, _index: u64, _event: Event) -> Result<Turn, Self::Error> {
        Ok(Turn::Go)
    }

    /// Take the event at `index`: run it here on `order` (a process's own node), or take
    /// it from its report ([`EventOrder::ran_elsewhere`]), or say it is not here yet.
    fn take(&mut self, order: &mut O, index: u64, event: Event) -> Result<Taken, Self::Error>;

    /// The event at `index` was taken: go on, or wait (samples held back that must go
    /// out first).
    fn taken(&mut self, _index: u64, _event: Event) -> Result<Turn, Self::Error> {
        Ok(Turn::Go)
    }
}

/// Take the run's events in order from where `cursor` stands, as far as `policy` lets it
/// (module docs for the order). Never blocks: [`Drew::Waiting`] returns to be called again.
///
/// # Errors
/// The policy's, from [`EventPolicy::turn`] or [`EventPolicy::take`] (the cursor stays on
/// the event, not taken) or from [`EventPolicy::taken`] (the event was taken; the cursor is
/// past it). An event that ended the run and whose `taken` failed returns the error.
pub fn drive_events<O, P>(
    order: &mut O,
    cursor: &mut Cursor,
    policy: &mut P,
    stop: Option<&StopFlag>,
) -> Result<Drew, P::Error>
where
    O: EventOrder + ?Sized,
    P: EventPolicy<O> + ?Sized,
{
    loop {
        if stop.is_some_and(StopFlag::is_stopped) {
            return Ok(Drew::Stopped);
        }
        if cursor.limit.is_some_and(|l| cursor.index >= l) {
            return Ok(Drew::Limit);
        }
        let event = match cursor.next {
            Some(e) => e,
            None => match order.next_event() {
                Some(e) => *cursor.next.insert(e),
                None => return Ok(Drew::Exhausted),
            },
        };
        let index = cursor.index;
        if policy.turn(index, event)? == Turn::Wait {
            return Ok(Drew::Waiting);
        }
        let over = match policy.take(order, index, event)? {
            Taken::Ran { over } => over,
            Taken::NotYet => return Ok(Drew::Waiting),
        };
        cursor.next = None;
        cursor.index += 1;
        let then = policy.taken(index, event)?;
        if over {
            return Ok(Drew::Over);
        }
        if then == Turn::Wait {
            return Ok(Drew::Waiting);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::RunConfig;
    use crate::runcore::{CoreOptions, Step};
    use crate::scheduler::EndReason;
    use ratelab_core::node::Flow;

    fn core(cfg: &RunConfig) -> RunCore {
        let opts = CoreOptions {
            keep_trace: true,
            ..CoreOptions::default()
        };
        RunCore::new(cfg, Box::new(crate::policy::Scripted), opts).unwrap()
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
    impl EventPolicy<RunCore> for Here {
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
        fn take(&mut self, core: &mut RunCore, _: u64, event: Event) -> Result<Taken, EndReason> {
            let (flow, _) = core.run_event(event)?;
            Ok(Taken::Ran {
                over: flow == Flow::Stop,
            })
        }
        fn taken(&mut self, index: u64, event: Event) -> Result<Turn, EndReason> {
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
            match drive_events(&mut c, &mut cursor, &mut p, None).unwrap() {
                Drew::Waiting => continue,
                other => break other,
            }
        };
        assert_eq!(drew, Drew::Exhausted);
        assert!(calls > 1 && p.waited_at.len() == calls - 1);
        let indices: Vec<u64> = p.taken.iter().map(|(i, _)| *i).collect();
        assert_eq!(indices, (0..cursor.index()).collect::<Vec<_>>());
        // Every event taken once, in order, whatever the waits between.
        c.finish_at_duration();
        assert_eq!(format!("{:?}", c.metrics()), stepped_metrics(&cfg));
    }

    /// Takes each event as run elsewhere, from a script of compute times; not yet for the
    /// events at `late` the first time they are asked.
    struct Reports {
        compute: Vec<Nanos>,
        late: Vec<u64>,
        took: Vec<Event>,
    }
    impl<O: EventOrder> EventPolicy<O> for Reports {
        type Error = String;
        fn take(&mut self, order: &mut O, index: u64, event: Event) -> Result<Taken, String> {
            if let Some(k) = self.late.iter().position(|&i| i == index) {
                self.late.remove(k);
                return Ok(Taken::NotYet);
            }
            let compute = *self.compute.get(index as usize).ok_or("no report")?;
            order.ran_elsewhere(event, compute);
            self.took.push(event);
            Ok(Taken::Ran { over: false })
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
            match drive_events(&mut follower, &mut cursor, &mut p, None) {
                Ok(Drew::Waiting) => {
                    waits += 1;
                    // The event not yet taken is kept, not drawn again.
                    assert_eq!(cursor.next(), Some(events[cursor.index() as usize]));
                }
                other => break other,
            }
        };
        assert_eq!((drew, waits, cursor.index()), (Ok(Drew::Exhausted), 2, n));
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
        let drew = drive_events(&mut elsewhere, &mut cursor, &mut p, None);
        assert_eq!(
            (drew, cursor.index(), cursor.left()),
            (Ok(Drew::Limit), n / 2, 0)
        );
        assert_eq!(cursor.next(), None, "nothing drawn at the limit");
        cursor.limit = Some(n);
        assert_eq!(cursor.left(), n - n / 2);
        // Goes on from the limit, at the event after the last taken.
        let drew = drive_events(&mut elsewhere, &mut cursor, &mut p, None);
        assert_eq!((drew, cursor.index()), (Ok(Drew::Limit), n));
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
        let drew = drive_events(&mut c, &mut cursor, &mut p, None);
        assert_eq!(drew, Err("no report".to_string()));
        assert_eq!(cursor.index(), 5);
        assert!(cursor.next().is_some(), "the event that failed is kept");
        let stop = StopFlag::new();
        stop.stop();
        let drew = drive_events(&mut c, &mut cursor, &mut p, Some(&stop));
        assert_eq!((drew, cursor.index()), (Ok(Drew::Stopped), 5));
    }

    /// Runs every event here; the event at `hold` ends the run when `over`, and after
    /// taking it the policy asks to wait (samples held back) when `wait`.
    struct HoldAfter {
        hold: u64,
        over: bool,
        wait: bool,
    }
    impl EventPolicy<RunCore> for HoldAfter {
        type Error = EndReason;
        fn take(
            &mut self,
            core: &mut RunCore,
            index: u64,
            event: Event,
        ) -> Result<Taken, EndReason> {
            core.run_event(event)?;
            Ok(Taken::Ran {
                over: self.over && index == self.hold,
            })
        }
        fn taken(&mut self, index: u64, _event: Event) -> Result<Turn, EndReason> {
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
        let drew = drive_events(&mut c, &mut cursor, &mut p, None);
        assert_eq!((drew, cursor.index()), (Ok(Drew::Over), 10));
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
        let drew = drive_events(&mut c, &mut cursor, &mut p, None);
        assert_eq!(
            (drew, cursor.index(), cursor.next()),
            (Ok(Drew::Waiting), 5, None)
        );
        p.hold = u64::MAX;
        let drew = drive_events(&mut c, &mut cursor, &mut p, None);
        assert_eq!(drew, Ok(Drew::Exhausted), "on from the event after it");

        let mut c = core(&cfg);
        let mut cursor = Cursor::default();
        let mut p = HoldAfter {
            hold: 4,
            over: true,
            wait: true,
        };
        let drew = drive_events(&mut c, &mut cursor, &mut p, None);
        assert_eq!((drew, cursor.index()), (Ok(Drew::Over), 5));
    }
}
