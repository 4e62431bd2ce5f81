//! The span of run time a recording keeps the plots of (`--record-window`), for runs too
//! long to record whole.

use ratelab_core::time::Nanos;

/// The span of run time a recording keeps the step rows of (`--record-window FROM:UNTIL`,
/// seconds): a long run's recording as large as the user asks, not as long as the run. The
/// settings, the events (changes, faults, QoS and liveliness events, the end) and the
/// summary cover the whole run, and the recording says which span its plots hold. A fall
/// is recorded wherever it happens.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordWindow {
    /// The first run time recorded.
    pub from: Nanos,
    /// The last run time recorded; `None`: to the end.
    pub until: Option<Nanos>,
}

impl RecordWindow {
    /// Parse `FROM:UNTIL` in seconds of run time, either side empty (`3600:3660`, `:60`,
    /// `86340:`), each within [`ratelab_core::limits::MAX_DURATION_S`].
    ///
    /// # Errors
    /// One line saying what is wrong.
    pub fn parse(s: &str) -> Result<RecordWindow, String> {
        let (a, b) = s.split_once(':').ok_or_else(|| {
            format!("'{s}' is not FROM:UNTIL in seconds of run time (e.g. 3600:3660, :60, 600:)")
        })?;
        let secs = |x: &str, what: &str| -> Result<Option<Nanos>, String> {
            let x = x.trim();
            if x.is_empty() {
                return Ok(None);
            }
            let v: f64 = x
                .parse()
                .map_err(|_| format!("{what} '{x}' is not a number of seconds"))?;
            if !(v.is_finite() && (0.0..=ratelab_core::limits::MAX_DURATION_S).contains(&v)) {
                return Err(ratelab_core::limits::refusal(
                    format!(
                        "{what} {v} s is outside 0 … {} s",
                        ratelab_core::limits::MAX_DURATION_S
                    ),
                    "MAX_DURATION_S",
                ));
            }
            Ok(Nanos::from_secs_f64(v))
        };
        let from = secs(a, "the window's start")?.unwrap_or(Nanos::ZERO);
        let until = secs(b, "the window's end")?;
        if until.is_some_and(|u| u < from) {
            return Err(format!("the window '{s}' ends before it starts"));
        }
        Ok(RecordWindow { from, until })
    }

    /// Is run time `t` inside?
    pub fn contains(&self, t: Nanos) -> bool {
        t >= self.from && self.until.is_none_or(|u| t <= u)
    }

    /// The span in words: `run time 3600–3660 s`, `run time from 600 s`.
    pub fn describe(&self) -> String {
        let s = |t: Nanos| format!("{}", t.as_secs_f64());
        match self.until {
            Some(u) => format!("run time {}–{} s", s(self.from), s(u)),
            None => format!("run time from {} s", s(self.from)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::RecordWindow;
    use ratelab_core::time::Nanos;

    #[test]
    fn a_window_parses_either_side_open_and_refuses_the_rest() {
        let w = RecordWindow::parse("3600:3660").unwrap();
        assert_eq!(
            (w.from, w.until),
            (Nanos(3_600_000_000_000), Some(Nanos(3_660_000_000_000)))
        );
        assert!(w.contains(Nanos(3_600_000_000_000)) && w.contains(Nanos(3_660_000_000_000)));
        assert!(!w.contains(Nanos(3_599_000_000_000)) && !w.contains(Nanos(3_661_000_000_000)));
        assert_eq!(w.describe(), "run time 3600–3660 s");
        let open = RecordWindow::parse("600:").unwrap();
        assert_eq!(open.until, None);
        assert_eq!(open.describe(), "run time from 600 s");
        assert!(open.contains(Nanos(1_000_000 * 1_000_000_000)));
        assert_eq!(RecordWindow::parse(":0.5").unwrap().from, Nanos::ZERO);
        for (bad, says) in [
            ("5", "FROM:UNTIL"),
            ("a:5", "not a number"),
            ("5:2", "ends before it starts"),
            ("-1:", "outside"),
            ("1e12:", "ratelab::limits::MAX_DURATION_S"),
            ("NaN:", "outside"),
        ] {
            let e = RecordWindow::parse(bad).unwrap_err();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }
}
