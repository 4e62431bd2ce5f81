//! The run's journal: every telemetry message the lab was told, kept (within
//! [`MAX_JOURNAL`] messages and [`MAX_JOURNAL_BYTES`]) so that a seek back
//! ([`Telemetry::Rewound`]) shows the run as it was then, by folding the journal again up to
//! that run time, from the nearest checkpoint of the folded view ([`super::checkpoints`]).

use super::{App, MAX_JOURNAL, MAX_JOURNAL_BYTES};
use ratelab::session::Telemetry;
use ratelab::Nanos;

impl App {
    /// Fold one telemetry message, and keep it in the run's journal (a seek back shows the
    /// run as it was by folding the journal again up to then).
    pub fn on_telemetry(&mut self, t: Telemetry) {
        if self.held_for_review(&t) {
            return;
        }
        if !self.rewinding {
            self.seek_answered(&t);
        }
        match t {
            // Counted by `seek_answered` above; nothing to show.
            Telemetry::Sought { .. } => {}
            Telemetry::Rewound { at } => {
                self.rewind(at);
                // Only the virtual clock scrubs in the engine: a run started under the real
                // clock and switched since is back under the virtual one.
                self.clock = ratelab::ClockKind::Virtual.to_string();
            }
            Telemetry::Started { .. } => {
                let reloaded = if self.rewinding {
                    None
                } else {
                    // A reload keeps the run before as a ghost; any other new run drops it.
                    let line = self.reloading.take();
                    self.ghost = match line {
                        Some(_) => std::mem::take(&mut self.whole),
                        None => Vec::new(),
                    };
                    line
                };
                self.journal.clear();
                self.journal_bytes = 0;
                self.journal_full = false;
                self.checkpoints.clear();
                self.fold(t.clone());
                self.journal.push((self.now, t));
                if !self.rewinding {
                    // Said again when the run ends ([`App::on_ended`]).
                    self.run_reload = reloaded.clone();
                }
                if let Some(line) = reloaded {
                    self.say(line);
                }
            }
            // A status while paused repeats its instant: the newest of an instant stands.
            Telemetry::Status { now, .. }
                if self.journal.last().is_some_and(|(at, last)| {
                    *at == now && matches!(last, Telemetry::Status { .. })
                }) =>
            {
                self.fold(t.clone());
                if let Some(last) = self.journal.last_mut() {
                    *last = (self.now, t);
                }
                self.journal_replaced_last();
            }
            t => {
                self.fold(t.clone());
                let bytes = t.approx_bytes();
                if self.journal.len() < MAX_JOURNAL
                    && self.journal_bytes.saturating_add(bytes) <= MAX_JOURNAL_BYTES
                {
                    self.journal_bytes += bytes;
                    self.journal.push((self.now, t));
                    self.checkpoint_if_due();
                } else {
                    self.journal_full = true;
                }
            }
        }
    }

    /// The run was put back at `at` ([`Telemetry::Rewound`], or a review): show it as it
    /// was then, by folding again what the run told up to then (what the screen showed at
    /// that run time, the clock it was under included).
    pub(super) fn rewind(&mut self, at: Nanos) {
        // A fault injected at an instant after `at` is not the branch's (the engine's log
        // keeps only the commands up to `at`), though the lab heard of it before `at` ran.
        self.faults.injected.retain(|f| f.at <= at);
        if self.journal_full {
            self.say(format!(
                "back at t={:.2} s: the run is too long to show as it was (its journal is full: {MAX_JOURNAL} messages or {} MiB); the figures go on from here",
                at.as_secs_f64(),
                MAX_JOURNAL_BYTES >> 20
            ));
            return;
        }
        // Paused it stays: what the journal folds again is the run as it ran (unpaused), and
        // a key pressed before the engine's next status must still move through the run (a
        // second ← read as "rate down" would branch it).
        let paused = self.paused;
        let upto = self.journal.partition_point(|(t, _)| *t <= at);
        // From the nearest checkpoint of the folded view at or before `at` (or from the
        // run's start): the messages after it, up to `at`, are folded again.
        let again = self.restore_for(upto, at);
        self.rewinding = true;
        for (_, t) in again {
            // A switch at the instant itself came after it (the engine scrubs back to where
            // a real-clock part began, not into it).
            if matches!(t, Telemetry::ClockSwitched { at: s, .. } if s >= at) {
                // The journal folded again lacks it from here: no checkpoint of it is taken
                // until this fold ends (a review puts the whole journal back).
                self.checkpoints.hold(true);
            } else {
                self.on_telemetry(t);
            }
        }
        self.checkpoints.hold(false);
        self.rewinding = false;
        self.paused = paused;
        // Folded again, the journal told of it: not the branch's (above).
        self.faults.injected.retain(|f| f.at <= at);
        self.now = at;
        self.say(back_notice(at));
        self.back_at = Some(at);
    }

    /// The message the footer shows: the last said; while that is a seek back's notice, the
    /// notice at the run time the paused run is now at (a step or a seek moves it on from
    /// where it was said), and nothing once the run goes on (space: it no longer waits
    /// there).
    pub(super) fn shown_message(&self) -> Option<String> {
        match self.back_at {
            Some(at) if self.message.as_deref() == Some(back_notice(at).as_str()) => {
                self.paused.then(|| back_notice(self.now))
            }
            _ => self.message.clone(),
        }
    }
}

/// What the lab says after a seek back to `at`.
fn back_notice(at: Nanos) -> String {
    format!(
        "back at t={:.3} s: a change or space branches the run here",
        at.as_secs_f64()
    )
}
