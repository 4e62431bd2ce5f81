//! Moving through a paused run: ← and → a tick (or, with Shift, a second) back or forward,
//! asked of the engine ([`Control::Seek`]), or of the recorded run while reviewing one. Keys
//! pressed faster than the engine answers go on from the last one asked, not from the
//! cursor the screen still shows.

use super::{App, Selected};
use ratelab::session::{Control, Telemetry};
use ratelab::Nanos;

impl App {
    /// Seek a second back or forward (`second`), else a period of the selected node (the
    /// actuator's when none is).
    pub(super) fn seek(&mut self, back: bool, second: bool) {
        let by = if second {
            Nanos::SECOND
        } else {
            let node = match self.selected {
                Some(Selected::Node(n)) => n,
                _ => self.graph.actuator,
            };
            ratelab::rate::period_for_hz(self.rate_of(node)).unwrap_or(Nanos::SECOND)
        };
        let from = self.seek_target.map_or(self.now, |(to, _)| to);
        let to = if back {
            from.saturating_sub(by)
        } else {
            from.saturating_add(by)
        };
        if self.reviewing() {
            self.review_to(to);
        } else {
            let out = self.seek_target.map_or(0, |(_, n)| n);
            self.seek_target = Some((to, out + 1));
            self.send(Control::Seek(to));
        }
    }

    /// The engine's answer to a seek ([`Telemetry::Sought`], one per seek, whether it moved
    /// the run or not): the last one out answered, the cursor is the engine's again. A new
    /// run, or one going on, has none out.
    pub(super) fn seek_answered(&mut self, t: &Telemetry) {
        self.seek_target = match (t, self.seek_target) {
            (Telemetry::Sought { .. }, Some((to, n))) if n > 1 => Some((to, n - 1)),
            // A run that could not start answers none it was sent.
            (
                Telemetry::Sought { .. } | Telemetry::Started { .. } | Telemetry::NotStarted(_),
                _,
            ) => None,
            (Telemetry::Status { paused: false, .. }, _) => None,
            (_, kept) => kept,
        };
    }
}
