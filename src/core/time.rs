//! Integer-nanosecond time: every stamp, period, deadline and clock reading in ratelab.
//!
//! The chapter accumulates float seconds (`due + period` in `f64`), which reorders
//! instants that should coincide: at a 10 Hz policy over a 50 Hz sensor, 37 of the 101
//! instants where both are due put the sensor's accumulated time *after* the policy's.
//! ratelab keeps time as whole nanoseconds since the start of a run, so `k * period`
//! is exact and ties are real ties, broken only by node priority.

use serde::{Deserialize, Serialize};
use std::fmt;
use std::ops::{Add, AddAssign, Sub};

pub use crate::limits::MAX_DURATION_S;
/// [`MAX_DURATION_S`] as run time.
pub const MAX_DURATION: Nanos = Nanos(MAX_DURATION_S as u64 * Nanos::SECOND.0);

/// A point in run time or a span of time, in whole nanoseconds (`u64`: about 584 years).
///
/// `Display` scales to the most readable unit: `850 ns`, `12.5 µs`, `20 ms`, `1.5 s`.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Nanos(pub u64);

impl Nanos {
    /// Zero: the start of a run.
    pub const ZERO: Nanos = Nanos(0);
    /// One millisecond.
    pub const MILLISECOND: Nanos = Nanos(1_000_000);
    /// One second.
    pub const SECOND: Nanos = Nanos(1_000_000_000);

    /// Whole nanoseconds.
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// From seconds, rounded to the nearest nanosecond. `None` if `secs` is not finite,
    /// negative, or too large for `u64` nanoseconds.
    pub fn from_secs_f64(secs: f64) -> Option<Nanos> {
        let ns = (secs * 1e9).round();
        (secs.is_finite() && secs >= 0.0 && ns < u64::MAX as f64).then_some(Nanos(ns as u64))
    }

    /// From whole milliseconds.
    pub const fn from_millis(ms: u64) -> Nanos {
        Nanos(ms * 1_000_000)
    }

    /// Seconds to the nanosecond, nine decimals, as text (`9.380000000`): exact where
    /// [`Nanos::as_secs_f64`] rounds, and read back exactly as a fault's time
    /// ([`crate::qos::Fault::parse`]).
    pub fn secs_exact(self) -> String {
        format!("{}.{:09}", self.0 / 1_000_000_000, self.0 % 1_000_000_000)
    }

    /// Seconds as `f64` (for display and reports only; never accumulated).
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 / 1e9
    }

    /// Milliseconds as `f64` (for display and reports only).
    pub fn as_millis_f64(self) -> f64 {
        self.0 as f64 / 1e6
    }

    /// Microseconds as `f64` (for display and reports only).
    pub fn as_micros_f64(self) -> f64 {
        self.0 as f64 / 1e3
    }

    /// `self - earlier`, or zero when `earlier` is later (a clamped difference).
    pub fn saturating_sub(self, earlier: Nanos) -> Nanos {
        Nanos(self.0.saturating_sub(earlier.0))
    }

    /// `self + other`, or `u64::MAX` ns (584 years: never) when that overflows. The executors
    /// add periods with it, so a rate as slow as the flags allow cannot overflow run time.
    pub fn saturating_add(self, other: Nanos) -> Nanos {
        Nanos(self.0.saturating_add(other.0))
    }

    /// As a `std::time::Duration`.
    pub fn to_duration(self) -> std::time::Duration {
        std::time::Duration::from_nanos(self.0)
    }
}

impl From<std::time::Duration> for Nanos {
    fn from(d: std::time::Duration) -> Self {
        Nanos(u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
    }
}

/// Saturating: a deadline past the end of `u64` time (a period of a rate like 1e-300 Hz)
/// is "never", not an overflow.
impl Add for Nanos {
    type Output = Nanos;
    fn add(self, rhs: Nanos) -> Nanos {
        Nanos(self.0.saturating_add(rhs.0))
    }
}

/// Saturating, as [`Add`].
impl AddAssign for Nanos {
    fn add_assign(&mut self, rhs: Nanos) {
        self.0 = self.0.saturating_add(rhs.0);
    }
}

impl Sub for Nanos {
    type Output = Nanos;
    /// Panics on underflow in debug builds; use [`Nanos::saturating_sub`] where the
    /// order is not guaranteed.
    fn sub(self, rhs: Nanos) -> Nanos {
        Nanos(self.0 - rhs.0)
    }
}

impl fmt::Display for Nanos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ns = self.0;
        let (value, unit) = if ns < 1_000 {
            return write!(f, "{ns} ns");
        } else if ns < 1_000_000 {
            (ns as f64 / 1e3, "µs")
        } else if ns < 1_000_000_000 {
            (ns as f64 / 1e6, "ms")
        } else {
            (ns as f64 / 1e9, "s")
        };
        // Up to three significant decimals, trailing zeros trimmed: 20 ms, 12.5 µs, 1.234 s.
        let text = format!("{value:.3}");
        let text = text.trim_end_matches('0').trim_end_matches('.');
        write!(f, "{text} {unit}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_scales_units() {
        assert_eq!(Nanos(850).to_string(), "850 ns");
        assert_eq!(Nanos(12_500).to_string(), "12.5 µs");
        assert_eq!(Nanos(20_000_000).to_string(), "20 ms");
        assert_eq!(Nanos(1_500_000_000).to_string(), "1.5 s");
        assert_eq!(Nanos(0).to_string(), "0 ns");
    }

    #[test]
    fn from_secs_rejects_bad_values() {
        assert_eq!(Nanos::from_secs_f64(0.02), Some(Nanos(20_000_000)));
        assert_eq!(Nanos::from_secs_f64(f64::NAN), None);
        assert_eq!(Nanos::from_secs_f64(-1.0), None);
        assert_eq!(Nanos::from_secs_f64(f64::INFINITY), None);
    }
}
