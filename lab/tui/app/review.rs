//! Looking back at a real-clock run that has ended: space freezes the screen on the run as
//! it was recorded, ← and → move through it (a tick of the selected node, Shift a second),
//! and space again — or a new run — leaves. Nothing branches: a real-clock run cannot run
//! again, so the engine is not asked; the lab folds its journal again up to the cursor
//! ([`super::journal`]), as a seek back under the virtual clock shows the run.

use super::{App, MAX_JOURNAL};
use ratelab::session::Telemetry;
use ratelab::Nanos;

/// Messages kept while reviewing, at most (the run has ended: only notices come).
const MAX_PENDING: usize = 4096;

/// A review of an ended real-clock run ([`App::toggle_review`]).
pub(in crate::tui) struct Review {
    /// The run's whole journal, as it was when the review began.
    journal: Vec<(Nanos, Telemetry)>,
    /// Where the run ended.
    end: Nanos,
    /// What came meanwhile, folded when the review ends.
    pending: Vec<Telemetry>,
}

impl App {
    /// A real-clock run that has ended can be reviewed (space).
    pub(in crate::tui) fn can_review(&self) -> bool {
        // A fall shows (its step says so) a moment before the engine's end arrives.
        let ended = self.ended_with.is_some() || matches!(self.verdict, super::Verdict::Fell(_));
        self.clock == "real" && ended && self.attached.is_none()
    }

    /// True while reviewing: ← and → move through the run.
    pub(in crate::tui) fn reviewing(&self) -> bool {
        self.review.is_some()
    }

    /// Space on an ended real-clock run: review it, or leave the review.
    pub(in crate::tui) fn toggle_review(&mut self) {
        if self.review.is_some() {
            self.leave_review();
            return;
        }
        if self.journal_full {
            self.say(format!(
                "the run is too long to review (its journal is full: {MAX_JOURNAL} messages)"
            ));
            return;
        }
        self.review = Some(Review {
            journal: self.journal.clone(),
            end: self.now,
            pending: Vec::new(),
        });
        self.say(format!(
            "review: ← → move through the run as recorded (0–{:.2} s) · space leaves",
            self.now.as_secs_f64()
        ));
    }

    /// Show the run as it was at `to` (within its end).
    pub(in crate::tui) fn review_to(&mut self, to: Nanos) {
        let Some(r) = &self.review else {
            return;
        };
        let to = to.min(r.end);
        self.journal = r.journal.clone();
        self.rewind(to);
        self.say(format!(
            "t={:.3} s as recorded: a real-clock run cannot run again (space leaves)",
            to.as_secs_f64()
        ));
    }

    /// Back to the run as it ended, then what came meanwhile.
    pub(in crate::tui) fn leave_review(&mut self) {
        let Some(r) = self.review.take() else {
            return;
        };
        self.journal = r.journal;
        self.rewind(r.end);
        self.say("the run as it ended".into());
        for t in r.pending {
            self.on_telemetry(t);
        }
    }

    /// While reviewing, a message from the engine: kept for when the review ends (`true`),
    /// or to be folded now (`false`: a new run, which ends the review first).
    pub(in crate::tui) fn held_for_review(&mut self, t: &Telemetry) -> bool {
        if self.rewinding {
            return false;
        }
        let Some(r) = &mut self.review else {
            return false;
        };
        match t {
            // A new run, or one that could not start: the review ends first.
            Telemetry::Started { .. } | Telemetry::NotStarted(_) => {
                self.leave_review();
                false
            }
            // The run has ended: its status repeats its last instant.
            Telemetry::Status { .. } => true,
            _ => {
                if r.pending.len() < MAX_PENDING {
                    r.pending.push(t.clone());
                }
                true
            }
        }
    }
}
