//! The courses the drive loop draws from ([`Course`]): a run core instant by instant, a
//! run core event by event, and a follower, which draws a run's order of events and runs
//! none of them. A run core is taken instant by instant as itself (every front end in one
//! process), and event by event only when it says so, as [`Events`] (a launch's process):
//! the mode is in the call, not in a type parameter.

use super::{Course, Taken};
use crate::runcore::{Follower, RunCore, Step};
use crate::scheduler::{Event, RunEnd};
use ratelab_core::node::Flow;
use ratelab_core::time::Nanos;

/// A run in this process, instant by instant ([`RunCore::step`]'s instants): paced before
/// it is made ready, ended at its duration or as interrupted by the loop.
impl Course<Nanos> for RunCore {
    fn end(&self) -> Option<RunEnd> {
        RunCore::end(self).cloned()
    }

    fn peek(&self) -> Option<Nanos> {
        self.next_instant()
    }

    fn draw(&mut self) -> Option<Nanos> {
        self.prepare_instant()
    }

    fn end_if_exhausted(&mut self) -> bool {
        self.finish_at_duration();
        true
    }

    fn end_on_stop(&mut self) -> Option<RunEnd> {
        Some(self.interrupt())
    }

    fn run_here(&mut self, t: Nanos) -> Taken {
        match self.run_prepared(t) {
            Step::Ran { ticked, .. } => Taken::Ran {
                over: false,
                ticked,
            },
            Step::Ended(_) => Taken::Ran {
                over: true,
                ticked: 0,
            },
        }
    }
}

/// A run core taken event by event (a course of [`Event`]s, [`super::drive`]), for a run
/// across processes: `drive(&mut Events(&mut core), …)`. It derefs to the core, so a
/// policy's code reads as the core's.
pub struct Events<'a>(pub &'a mut RunCore);

impl std::ops::Deref for Events<'_> {
    type Target = RunCore;
    fn deref(&self) -> &RunCore {
        self.0
    }
}

impl std::ops::DerefMut for Events<'_> {
    fn deref_mut(&mut self) -> &mut RunCore {
        self.0
    }
}

/// A run across processes, this process's share of it, event by event
/// ([`RunCore::next_event`]): each event run here ([`RunCore::run_event`]) or taken from its
/// report ([`RunCore::ran_elsewhere`], the policy's). An event run here that stops the run
/// or fails ends it (the loop's [`super::Drove::Ended`]); what a stop or the run's duration
/// reached means is the caller's ([`super::Drove::Stopped`], [`super::Drove::Exhausted`]).
impl Course<Event> for Events<'_> {
    fn end(&self) -> Option<RunEnd> {
        self.0.end().cloned()
    }

    fn draw(&mut self) -> Option<Event> {
        self.0.next_event()
    }

    fn run_here(&mut self, event: Event) -> Taken {
        let ticked = match event {
            Event::Start { node, .. } => 1u64 << (node % 64),
            Event::Publish { .. } => 0,
        };
        match self.0.run_event(event) {
            Ok((flow, _)) => Taken::Ran {
                over: flow == Flow::Stop,
                ticked,
            },
            Err(_) => Taken::Ran { over: true, ticked }, // the core has ended: failed
        }
    }
}

/// The launcher's order of a run across processes: every event taken from its process's
/// report (the policy's [`super::DrivePolicy::take`]); a follower runs none here.
impl Course<Event> for Follower {
    fn end(&self) -> Option<RunEnd> {
        None
    }

    fn draw(&mut self) -> Option<Event> {
        self.next_event()
    }

    /// A follower runs no node: an event is here only once its report is.
    fn run_here(&mut self, _event: Event) -> Taken {
        Taken::NotYet
    }
}
