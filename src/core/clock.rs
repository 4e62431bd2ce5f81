//! Clocks: where "now" comes from. The real scheduler reads a monotonic clock; tests and
//! the virtual scheduler use a clock that only moves when told to.

use crate::time::Nanos;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Instant;

/// A source of run time (nanoseconds since the run started).
pub trait Clock: Send + Sync {
    /// The current run time.
    fn now(&self) -> Nanos;
}

/// The wall's monotonic clock (`std::time::Instant`), zeroed at construction.
#[derive(Debug, Clone, Copy)]
pub struct MonotonicClock {
    start: Instant,
}

impl MonotonicClock {
    /// A clock reading zero now.
    pub fn start() -> Self {
        Self {
            start: Instant::now(),
        }
    }

    /// A clock reading zero at `start` (which may be in the future: it then reads zero
    /// until `start`).
    pub fn starting_at(start: Instant) -> Self {
        Self { start }
    }

    /// The `Instant` at which this clock reads `t` (for absolute-deadline sleeps). A `t`
    /// beyond what `Instant` can hold gives an instant about a century away.
    pub fn instant_at(&self, t: Nanos) -> Instant {
        self.start
            .checked_add(t.to_duration())
            .or_else(|| {
                self.start
                    .checked_add(std::time::Duration::from_secs(100 * 365 * 86_400))
            })
            .unwrap_or(self.start)
    }
}

impl Clock for MonotonicClock {
    fn now(&self) -> Nanos {
        Nanos::from(self.start.elapsed())
    }
}

/// A clock that moves only when set: the virtual scheduler's time, and a mock for tests.
#[derive(Debug, Default)]
pub struct ManualClock {
    now_ns: AtomicU64,
}

impl ManualClock {
    /// A clock reading zero.
    pub fn new() -> Self {
        Self::default()
    }

    /// Move the clock to `t`. Time never runs backwards: an earlier `t` is ignored.
    pub fn advance_to(&self, t: Nanos) {
        self.now_ns.fetch_max(t.0, Ordering::SeqCst);
    }
}

impl Clock for ManualClock {
    fn now(&self) -> Nanos {
        Nanos(self.now_ns.load(Ordering::SeqCst))
    }
}

/// Which executor runs the graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClockKind {
    /// Deterministic discrete-event executor (one thread, virtual time).
    Virtual,
    /// One OS thread per node against the monotonic clock.
    Real,
}

impl ClockKind {
    /// `virtual` or `real`.
    pub fn as_str(self) -> &'static str {
        match self {
            ClockKind::Virtual => "virtual",
            ClockKind::Real => "real",
        }
    }

    /// The other clock.
    pub fn other(self) -> ClockKind {
        match self {
            ClockKind::Virtual => ClockKind::Real,
            ClockKind::Real => ClockKind::Virtual,
        }
    }
}

impl std::fmt::Display for ClockKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A clock's name that is neither `virtual` nor `real`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("--clock must be 'real' or 'virtual', got '{0}'")]
pub struct UnknownClock(pub String);

impl std::str::FromStr for ClockKind {
    type Err = UnknownClock;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "virtual" => Ok(ClockKind::Virtual),
            "real" => Ok(ClockKind::Real),
            other => Err(UnknownClock(other.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn manual_clock_is_monotonic() {
        let c = ManualClock::new();
        c.advance_to(Nanos(50));
        c.advance_to(Nanos(10));
        assert_eq!(c.now(), Nanos(50));
    }
}
