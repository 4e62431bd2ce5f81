//! One drive loop for a run under the virtual clock: [`drive`] owns the order of what
//! happens around each unit of a run it takes — the stop flag, the commands taken between
//! units, pacing against the wall, `/clock`, the end — and a [`DrivePolicy`] supplies only
//! what differs between front ends: its pacing, its commands and its event source (whether
//! a unit's turn has come, and whether it runs here or is taken from another process's
//! report).
//!
//! A unit ([`Unit`]) is what the loop takes in one turn, drawn from a [`Course`]:
//! - **an instant** (`Nanos`) of a [`RunCore`], run whole: the headless run and everything
//!   built on it (`ratelab_drivers::run`: `sweep`, `cliff`, `bench`, `replay`, the
//!   exercises), the lab's trial judge, ex13's count of `/clock` and the lab's paced
//!   session (`ratelab_drivers::session`);
//! - **an event** ([`Event`]: a tick's start, or its held outputs going out) of a
//!   [`RunCore`] that says so ([`Events`]) or of a [`Follower`], for a run across
//!   processes, where each event's node runs in one process and the others take it from
//!   its report: a process's lockstep (`ratelab_distributed::process`) and the launcher
//!   that follows its processes.
//!
//! The loop blocks only where its policy asks it to: a pacing sleep ([`Pace::Sleep`], at
//! most [`MAX_PACING_SLEEP`]) or a policy's own wait for its controls. A lockstep's policy
//! never does: it runs on Zenoh's receive thread too, and where an event's input or report
//! is not here yet the loop returns [`Drove::Waiting`], the [`Cursor`] keeping its place, and
//! is called again when something comes in.
//!
//! Under the real clock the graph runs on the executor's threads, not unit by unit: the
//! front end's controls are taken meanwhile by [`watch_real`] ([`RealPolicy`]).
//!
//! # The order around a unit
//! 1. The stop flag: set, a run taken instant by instant ends as interrupted at the newest
//!    instant run ([`Drove::Ended`]); one taken event by event returns [`Drove::Stopped`]
//!    (what a stop means is the caller's: a process's error, the launcher's grace period).
//! 2. The limit ([`Cursor::limit`]): the run's count of units, once known; none at or past
//!    it is taken ([`Drove::Limit`]).
//! 3. When no unit is drawn yet (between units):
//!    1. [`DrivePolicy::intake`]: commands and controls (a command applied here takes effect
//!       before the next instant and is logged at it, [`RunCore::apply`]). `Hold` goes back
//!       to 1 (the policy waited), `Leave` returns [`Drove::Left`] with the run *not*
//!       ended (the lab's clock switch goes on with it).
//!    2. The end: once the run has ended, [`DrivePolicy::at_end`] says whether to hold (the
//!       lab keeps an ended run, which a seek back can take up again) or to return it.
//!    3. Pacing ([`DrivePolicy::pace`]) for the next unit's time where the course can tell
//!       it before drawing it ([`Course::peek`]: an instant's); a sleep goes back to 1, so
//!       commands and the stop flag are seen while waiting.
//!    4. The unit drawn ([`Course::draw`]): an instant made ready (the commands scheduled
//!       at or before it applied, [`crate::command::TimedCommand`]), or the next event. An
//!       instant peeked but moved past the duration by a phase change goes back to 1. None
//!       left: a run taken instant by instant ends at its duration (back to 1, for its
//!       end); otherwise [`Drove::Exhausted`].
//! 4. A unit drawn at another time than was paced (a scheduled phase change moved the
//!    instant later, or an event) is paced now, with no intake: a command taken now would
//!    be logged after the scheduled ones of its instant, where a replay puts it before them.
//!    A drawn unit is kept in the cursor until it is taken, through any wait.
//! 5. [`DrivePolicy::turn`]: the event source's say (the launcher's horizon, which thread
//!    may run it); `Wait` returns [`Drove::Waiting`].
//! 6. `/clock` ([`ClockOut`]) told the unit's time (once per unit), and the unit taken
//!    ([`DrivePolicy::take`]): run here ([`Course::run_here`], the default), or from its
//!    report, or not yet ([`Drove::Waiting`]).
//! 7. The cursor moves on and [`DrivePolicy::taken`] is told. A unit that stopped the run or
//!    failed ends it: [`DrivePolicy::at_end`] for a course that knows its end, else
//!    [`Drove::Over`].
//!
//! An error from the policy ends the loop ([`drive`]'s errors). Pacing and `/clock` change
//! only *when* a unit is taken, never what it is: a driven run equals [`RunCore::step`]
//! called to the end, byte for byte, and a run taken event by event, here or from reports,
//! equals the one process's run (`drive/tests.rs`; across processes,
//! `tests/it/distributed.rs`).

mod course;
mod pacer;
mod real;
#[cfg(test)]
mod tests;

pub use course::Events;
pub use pacer::Pacer;
pub use real::{watch_real, RealPolicy};

#[cfg(doc)]
use super::{Follower, RunCore};
use crate::scheduler::{Event, RunEnd, StopFlag};
use ratelab_core::time::Nanos;
use std::convert::Infallible;
use std::time::Duration;

/// The longest a pacing sleep lasts before the loop looks at its stop flag and commands
/// again: 10 ms.
pub const MAX_PACING_SLEEP: Duration = Duration::from_millis(10);

/// Where a run's time goes out as it advances: ROS 2's `/clock` (`ratelab_ros2::Bridge`),
/// or a count of it (ex13). Told each unit's run time just before it is taken: each
/// instant's, for a run taken instant by instant (a launch's processes, taken event by
/// event, are given none: `docs/design/drive-loop.md`, risk 2).
pub trait ClockOut {
    /// The run is about to run the instant at `t` (run time, ns).
    fn clock(&self, t: Nanos);
}

/// What the drive loop takes in one turn: an instant (its run time, `Nanos`) or an event
/// ([`Event`]).
pub trait Unit: Copy {
    /// Its run time (ns).
    fn at(&self) -> Nanos;
}

impl Unit for Nanos {
    fn at(&self) -> Nanos {
        *self
    }
}

impl Unit for Event {
    fn at(&self) -> Nanos {
        self.node_at().1
    }
}

/// What the drive loop draws its units `U` from (implemented in `drive/course.rs`): a
/// [`RunCore`] instant by instant (`Course<Nanos>`), a run core event by event ([`Events`],
/// `Course<Event>`), or a [`Follower`] (`Course<Event>`), which draws a run's order of
/// events and runs none.
pub trait Course<U: Unit> {
    /// How the run ended, once it has; `None` for a course that does not know (a
    /// follower: its policy learns the end from the reports).
    fn end(&self) -> Option<RunEnd>;

    /// The next unit's time where it is known before the unit is drawn (an instant's,
    /// before the commands scheduled at it apply), so that it is paced with commands still
    /// taken; `None`: known once drawn, or none left.
    fn peek(&self) -> Option<Nanos> {
        None
    }

    /// The next unit, made ready (an instant: the commands scheduled at or before it
    /// applied; an event: the clock moved on to it); `None` past the run's end or duration.
    fn draw(&mut self) -> Option<U>;

    /// Nothing left to draw: `true` when the course has ended the run at its duration (a
    /// run core taken instant by instant; the loop goes on to its end), `false` (the
    /// default) when that is the caller's to say ([`Drove::Exhausted`]).
    fn end_if_exhausted(&mut self) -> bool {
        false
    }

    /// The stop flag is set: the run's end, when the course ends it (interrupted at the
    /// newest instant run, instant by instant); `None` (the default): the caller's
    /// ([`Drove::Stopped`]).
    fn end_on_stop(&mut self) -> Option<RunEnd> {
        None
    }

    /// Take `unit` by running it here (the default of [`DrivePolicy::take`]).
    fn run_here(&mut self, unit: U) -> Taken;
}

/// What [`DrivePolicy::intake`] and [`DrivePolicy::at_end`] ask of the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Intake {
    /// Go on.
    Go,
    /// Take nothing now, and come back (through the stop flag) to intake. A policy that
    /// holds has waited for its controls (at most a few tens of ms), so the loop does not
    /// spin.
    Hold,
    /// Return [`Drove::Left`]; the run is not ended.
    Leave,
}

/// What [`DrivePolicy::pace`] asks before a unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pace {
    /// Take it now.
    Now,
    /// Not yet: sleep this long (the loop caps it at [`MAX_PACING_SLEEP`]), then look again.
    Sleep(Duration),
}

/// What [`DrivePolicy::turn`] and [`DrivePolicy::taken`] ask of the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Turn {
    /// Go on.
    Go,
    /// Return [`Drove::Waiting`]; the caller calls again when what it waits for comes.
    Wait,
}

/// How a unit was taken ([`DrivePolicy::take`], [`Course::run_here`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Taken {
    /// Taken: run here, or from its report.
    Ran {
        /// The run ends with this unit: its node stopped the run or failed.
        over: bool,
        /// The nodes that ticked in it, as bits (bit `i % 64` for node `i`, as
        /// [`super::Step::Ran`]); 0 for an instant that ended the run, and where the policy
        /// does not say (an event from a report; the lockstep's own events).
        ticked: u64,
    },
    /// Not yet: an input it must see, or its report, is still on its way.
    NotYet,
}

/// How [`drive`] returned.
#[derive(Clone, Debug, PartialEq)]
pub enum Drove {
    /// The run ended: at its duration, or a node stopped it or failed, and the policy let it
    /// go ([`DrivePolicy::at_end`]); or the stop flag ended it ([`Course::end_on_stop`]).
    Ended(RunEnd),
    /// The policy left ([`Intake::Leave`]) with the run not ended.
    Left,
    /// Waiting: for the policy's turn, an input or a report. Call again when it comes.
    Waiting,
    /// The unit just taken stopped the run or failed, in a course that does not know its
    /// end (a follower's, or an event taken from a report).
    Over,
    /// No unit left, in a course that leaves its end to the caller
    /// ([`Course::end_if_exhausted`]).
    Exhausted,
    /// Every unit up to [`Cursor::limit`] is taken.
    Limit,
    /// The stop flag was set, in a course that leaves what it means to the caller
    /// ([`Course::end_on_stop`]).
    Stopped,
}

/// Where a run stands between calls of [`drive`]: the next unit's place in the run's order,
/// the unit once drawn and until it is taken, the time last paced, and the run's count of
/// units once it is known.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cursor<U> {
    index: u64,
    next: Option<U>,
    paced: Option<Nanos>,
    /// `/clock` was told the drawn unit's time (once, however often it is not yet here).
    clocked: bool,
    /// The run's units, once known (the launcher's word at a run's end): none at or past
    /// this index is taken.
    pub limit: Option<u64>,
}

impl<U> Default for Cursor<U> {
    fn default() -> Self {
        Cursor {
            index: 0,
            next: None,
            paced: None,
            clocked: false,
            limit: None,
        }
    }
}

impl<U: Copy> Cursor<U> {
    /// A cursor at the run's `index`-th unit, none drawn: where a run whose first `index`
    /// units were taken stands.
    pub fn at(index: u64) -> Cursor<U> {
        Cursor {
            index,
            ..Cursor::default()
        }
    }

    /// The next unit's place in the run's order (0-based): the units taken so far.
    pub fn index(&self) -> u64 {
        self.index
    }

    /// The next unit, once drawn and until it is taken.
    pub fn next(&self) -> Option<U> {
        self.next
    }

    /// Units still to take before the limit (0 without one).
    pub fn left(&self) -> u64 {
        self.limit.map_or(0, |l| l.saturating_sub(self.index))
    }
}

/// What a front end supplies to [`drive`] for units `U` drawn from `C`: its pacing, its
/// commands and its event source (module docs for when each is asked). Every method but
/// the error's type has a default, so a policy writes only what differs: the headless
/// run's is its [`Pacer`] when offered to ROS 2, and nothing ([`Unpaced`]) otherwise.
pub trait DrivePolicy<U: Unit, C: Course<U> + ?Sized> {
    /// Why the run cannot go on (a report out of step, a report that cannot be sent);
    /// [`Infallible`] for a run in one process.
    type Error;

    /// Between units: take commands and controls (apply them with [`RunCore::apply`]).
    /// Called before every unit is drawn, and after a [`Intake::Hold`] or a pacing sleep.
    /// Taken instant by instant, that is between instants. Taken event by event it may be
    /// within an instant, where a command would be logged at the wrong instant: a run across
    /// processes takes no commands (its policies keep this default).
    fn intake(&mut self, _course: &mut C) -> Intake {
        Intake::Go
    }

    /// The next unit is at `t`: take it now, or sleep first.
    fn pace(&mut self, _t: Nanos) -> Pace {
        Pace::Now
    }

    /// The unit at `index`, drawn and paced, is next: take it now, or wait (past the
    /// launcher's horizon; on a thread that may not run it). Asked again after each wait.
    fn turn(&mut self, _index: u64, _unit: U) -> Result<Turn, Self::Error> {
        Ok(Turn::Go)
    }

    /// Take the unit at `index`: run it here (the default), or take it from its report
    /// (`RunCore::ran_elsewhere`), or say it is not here yet.
    fn take(&mut self, course: &mut C, _index: u64, unit: U) -> Result<Taken, Self::Error> {
        Ok(course.run_here(unit))
    }

    /// The unit at `index` was taken, `ticked` the nodes that ticked in it ([`Taken`]): go
    /// on, or wait (samples held back that must go out first). Told of a unit that ended the
    /// run too, before [`DrivePolicy::at_end`].
    fn taken(
        &mut self,
        _course: &mut C,
        _index: u64,
        _unit: U,
        _ticked: u64,
    ) -> Result<Turn, Self::Error> {
        Ok(Turn::Go)
    }

    /// The run has ended (`end`): [`Intake::Leave`] (the default) returns
    /// [`Drove::Ended`]; [`Intake::Hold`] (and `Go`, the same here) keeps the ended run. It
    /// is asked again after each intake that returns `Go`, so a policy that holds an ended
    /// run should return `Hold` from `intake` (after waiting for its controls) until it
    /// leaves.
    fn at_end(&mut self, _course: &mut C, _end: &RunEnd) -> Intake {
        Intake::Leave
    }
}

/// The policy with nothing to add: every unit as fast as it runs, here, no commands.
#[derive(Clone, Copy, Debug, Default)]
pub struct Unpaced;

impl<U: Unit, C: Course<U> + ?Sized> DrivePolicy<U, C> for Unpaced {
    type Error = Infallible;
}

/// Drive `course` from where `cursor` stands with `policy` (module docs for the order),
/// until the run ends and the policy lets it go, the policy leaves, or the loop must wait.
/// `stop` set ends the run ([`Course::end_on_stop`]); `clock` is told each unit's time once,
/// before it is taken.
///
/// Generic over the course and the policy, so the headless run's loop pays no dynamic call
/// per instant.
///
/// # Errors
/// The policy's, from [`DrivePolicy::turn`] or [`DrivePolicy::take`] (the cursor stays on the
/// unit, not taken) or from [`DrivePolicy::taken`] (the unit was taken; the cursor is past
/// it). A unit that ended the run and whose `taken` failed returns the error.
pub fn drive<U, C, P>(
    course: &mut C,
    cursor: &mut Cursor<U>,
    policy: &mut P,
    stop: Option<&StopFlag>,
    clock: Option<&dyn ClockOut>,
) -> Result<Drove, P::Error>
where
    U: Unit,
    C: Course<U> + ?Sized,
    P: DrivePolicy<U, C> + ?Sized,
{
    loop {
        if stop.is_some_and(StopFlag::is_stopped) {
            return Ok(course.end_on_stop().map_or(Drove::Stopped, Drove::Ended));
        }
        if cursor.limit.is_some_and(|l| cursor.index >= l) {
            return Ok(Drove::Limit);
        }
        let unit = match cursor.next {
            Some(unit) => unit,
            None => {
                match policy.intake(course) {
                    Intake::Go => {}
                    Intake::Hold => continue,
                    Intake::Leave => return Ok(Drove::Left),
                }
                if let Some(end) = course.end() {
                    match policy.at_end(course, &end) {
                        Intake::Leave => return Ok(Drove::Ended(end)),
                        Intake::Go | Intake::Hold => continue,
                    }
                }
                let peeked = course.peek();
                if let Some(t) = peeked {
                    if let Pace::Sleep(wait) = policy.pace(t) {
                        std::thread::sleep(wait.min(MAX_PACING_SLEEP));
                        continue;
                    }
                }
                cursor.paced = peeked;
                match course.draw() {
                    Some(unit) => {
                        cursor.clocked = false;
                        *cursor.next.insert(unit)
                    }
                    // Moved past the duration by a phase change: the end, next time round.
                    None if peeked.is_some() => continue,
                    None if course.end_if_exhausted() => continue, // its end, next time round
                    None => return Ok(Drove::Exhausted),
                }
            }
        };
        let t = unit.at();
        if cursor.paced != Some(t) {
            // Drawn at another time than paced: paced now, without intake (module docs).
            if let Pace::Sleep(wait) = policy.pace(t) {
                std::thread::sleep(wait.min(MAX_PACING_SLEEP));
                continue;
            }
            cursor.paced = Some(t);
        }
        let index = cursor.index;
        if policy.turn(index, unit)? == Turn::Wait {
            return Ok(Drove::Waiting);
        }
        if let Some(out) = clock.filter(|_| !cursor.clocked) {
            out.clock(t);
            cursor.clocked = true;
        }
        let (over, ticked) = match policy.take(course, index, unit)? {
            Taken::Ran { over, ticked } => (over, ticked),
            Taken::NotYet => return Ok(Drove::Waiting),
        };
        cursor.next = None;
        cursor.index += 1;
        let then = policy.taken(course, index, unit, ticked)?;
        if over {
            let Some(end) = course.end() else {
                return Ok(Drove::Over);
            };
            match policy.at_end(course, &end) {
                Intake::Leave => return Ok(Drove::Ended(end)),
                Intake::Go | Intake::Hold => continue,
            }
        }
        if then == Turn::Wait {
            return Ok(Drove::Waiting);
        }
    }
}
