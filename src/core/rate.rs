//! Rates: fixed periods in integer nanoseconds, and absolute-deadline waits for the real clock.
//!
//! A period is `round(1e9 / hz)` ns. The real scheduler never sleeps "for a period": it
//! sleeps *until* the next absolute deadline (`previous deadline + period`), so a late
//! wake-up does not push every later tick back (no drift). Plain `thread::sleep` wakes
//! 100–250 µs late on a shared Linux machine, so [`DeadlineWaiter::wait_until`] sleeps to `spin_margin`
//! before the deadline and spins the rest (the `spin_sleep` crate).

use crate::time::Nanos;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

/// The highest rate ratelab accepts, in Hz.
pub const MAX_HZ: f64 = 10_000.0;

/// The lowest rate ratelab accepts, in Hz: one tick in the longest run
/// ([`crate::limits::MAX_DURATION_S`], ten years, about 3.17e-9 Hz). Slower, a period would
/// not tick within any run, and past about 5.4e-11 Hz it would not fit its `u64`
/// nanoseconds (1e-300 Hz is a period of 1e309 s).
pub const MIN_HZ: f64 = 1.0 / crate::limits::MAX_DURATION_S;

/// The default spin margin: sleep to this long before a deadline, then spin.
pub const DEFAULT_SPIN_MARGIN: Nanos = Nanos(300_000);

/// The largest spin margin accepted (`--spin-margin-us` ≤ 1 000 000): one second. It must
/// also be below every node's period (`ratelab::config::RunConfig::validate`).
pub const MAX_SPIN_MARGIN: Nanos = Nanos(1_000_000_000);

/// How often a long wait looks at its stop condition: a stop request or the run's end is
/// noticed within this, however slow the node's rate.
pub const STOP_POLL: std::time::Duration = std::time::Duration::from_millis(10);

/// A rate that cannot be used.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("rate {}", rate_rule(*hz))]
pub struct InvalidRate {
    /// The rejected value, in Hz.
    pub hz: f64,
}

/// Why `hz` is refused as a rate, as a refusal says it after the setting's name, the value
/// short ([`crate::text::number`]): `must be a finite rate in (0, 10000] Hz, got 0`, or for
/// a positive rate below [`MIN_HZ`] `must be at least 3.171e-9 Hz, one tick in the longest
/// run (…), got 1e-300`.
pub fn rate_rule(hz: f64) -> String {
    let got = crate::text::number(hz);
    if hz > 0.0 && hz < MIN_HZ {
        format!(
            "must be at least {MIN_HZ:.3e} Hz, one tick in the longest run ({} s, ratelab::limits::MAX_DURATION_S), got {got}",
            crate::limits::MAX_DURATION_S
        )
    } else {
        format!("must be a finite rate in (0, {MAX_HZ}] Hz, got {got}")
    }
}

/// The period of a rate: `round(1e9 / hz)` nanoseconds.
///
/// # Errors
/// [`InvalidRate`] when `hz` is not finite or not in [[`MIN_HZ`], [`MAX_HZ`]].
pub fn period_for_hz(hz: f64) -> Result<Nanos, InvalidRate> {
    if (MIN_HZ..=MAX_HZ).contains(&hz) {
        Ok(Nanos((1e9 / hz).round() as u64))
    } else {
        Err(InvalidRate { hz })
    }
}

/// A node's rate, shareable so it can be changed while the graph runs (the lab's keys).
/// The change takes effect from the node's next tick: the scheduler reads the period when
/// it schedules the following deadline.
#[derive(Clone, Debug)]
pub struct Rate {
    period_ns: Arc<AtomicU64>,
    hz_bits: Arc<AtomicU64>,
}

impl Rate {
    /// A rate of `hz`.
    ///
    /// # Errors
    /// [`InvalidRate`] as for [`period_for_hz`].
    pub fn new(hz: f64) -> Result<Self, InvalidRate> {
        let period = period_for_hz(hz)?;
        Ok(Self {
            period_ns: Arc::new(AtomicU64::new(period.0)),
            hz_bits: Arc::new(AtomicU64::new(hz.to_bits())),
        })
    }

    /// The current period.
    pub fn period(&self) -> Nanos {
        Nanos(self.period_ns.load(Ordering::Acquire))
    }

    /// The current rate as set, in Hz.
    pub fn hz(&self) -> f64 {
        f64::from_bits(self.hz_bits.load(Ordering::Acquire))
    }

    /// Change the rate; every clone of this `Rate` sees it.
    ///
    /// # Errors
    /// [`InvalidRate`]; the rate is unchanged.
    pub fn set_hz(&self, hz: f64) -> Result<(), InvalidRate> {
        let period = period_for_hz(hz)?;
        self.hz_bits.store(hz.to_bits(), Ordering::Release);
        self.period_ns.store(period.0, Ordering::Release);
        Ok(())
    }
}

/// Waits for absolute deadlines: sleep until `margin` before, then spin.
#[derive(Clone, Copy, Debug)]
pub struct DeadlineWaiter {
    sleeper: spin_sleep::SpinSleeper,
}

impl DeadlineWaiter {
    /// A waiter that spins the last `margin` before each deadline (0 = never spin).
    pub fn new(margin: Nanos) -> Self {
        let margin_ns = u32::try_from(margin.0).unwrap_or(u32::MAX);
        Self {
            sleeper: spin_sleep::SpinSleeper::new(margin_ns)
                .with_spin_strategy(spin_sleep::SpinStrategy::YieldThread),
        }
    }

    /// Block until `deadline` (returns at once if it has passed).
    pub fn wait_until(&self, deadline: Instant) {
        let now = Instant::now();
        if deadline > now {
            self.sleeper.sleep(deadline - now);
        }
    }

    /// Block until `deadline`, or until `stop()` returns true, whichever comes first: a
    /// wait longer than [`STOP_POLL`] plus the spin margin sleeps in [`STOP_POLL`] slices,
    /// checking `stop` between them, then approaches the deadline as
    /// [`DeadlineWaiter::wait_until`] does (the same precision at the deadline). Returns
    /// `true` when the deadline was reached, `false` when `stop` cut the wait short.
    pub fn wait_until_or(&self, deadline: Instant, stop: &dyn Fn() -> bool) -> bool {
        let slice_limit = STOP_POLL
            + std::time::Duration::from_nanos(u64::from(self.sleeper.native_accuracy_ns()));
        loop {
            if stop() {
                return false;
            }
            let now = Instant::now();
            if deadline <= now {
                return true;
            }
            let left = deadline - now;
            if left <= slice_limit {
                self.sleeper.sleep(left);
                return true;
            }
            std::thread::sleep(STOP_POLL);
        }
    }
}

impl Default for DeadlineWaiter {
    fn default() -> Self {
        Self::new(DEFAULT_SPIN_MARGIN)
    }
}

/// The next absolute deadline after a tick that was scheduled for `scheduled`, given the
/// current time `now` and the period. On time, that is `scheduled + period`. When a tick
/// ran so late that one or more whole deadlines have already passed, those ticks are
/// skipped and the schedule stays on its grid (`scheduled + k·period`, the first one
/// after `now`), as ROS timers do, rather than firing a burst to catch up (rcl's
/// `rcl_timer_call`, rcl/src/rcl/timer.c). Returns the deadline and the number of ticks
/// skipped.
///
/// One difference from rcl, on purpose: a tick late by *exactly* whole periods skips the
/// deadline it lands on (rcl calls the timer again at once when `next == now`). Under a real
/// clock the call always comes a little after, so rcl skips too; under the virtual clock
/// exact instants are common (a 30 ms callback ends on a 20 ms grid every 60 ms), and
/// skipping keeps the virtual model what the real clock does.
pub fn next_deadline(scheduled: Nanos, now: Nanos, period: Nanos) -> (Nanos, u64) {
    let next = scheduled.saturating_add(period);
    if now < next || period.0 == 0 {
        return (next, 0);
    }
    let missed = (now.0 - next.0) / period.0 + 1;
    (
        Nanos(next.0.saturating_add(missed.saturating_mul(period.0))),
        missed,
    )
}

/// The first point of the grid `phase + k·period` (k ≥ 0) at or after `from`: where a node
/// whose ticks fall on that grid ticks next (a phase change, a process joining a run late).
pub fn first_on_grid(phase: Nanos, period: Nanos, from: Nanos) -> Nanos {
    if from <= phase || period.0 == 0 {
        return phase;
    }
    let k = (from.0 - phase.0).div_ceil(period.0);
    Nanos(phase.0.saturating_add(k.saturating_mul(period.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periods_round_to_nanoseconds() {
        assert_eq!(period_for_hz(50.0), Ok(Nanos(20_000_000)));
        assert_eq!(period_for_hz(3.0), Ok(Nanos(333_333_333)));
        assert_eq!(period_for_hz(7.0), Ok(Nanos(142_857_143)));
        assert_eq!(period_for_hz(10_000.0), Ok(Nanos(100_000)));
    }

    #[test]
    fn bad_rates_are_rejected() {
        for hz in [0.0, -5.0, f64::NAN, f64::INFINITY, 10_000.5, 1e-300, 3e-9] {
            assert!(period_for_hz(hz).is_err(), "{hz}");
        }
        // The slowest: one tick in the longest run, its period in range.
        let slowest = period_for_hz(MIN_HZ).unwrap();
        assert_eq!(slowest.0, 315_360_000_000_000_000);
        assert!(period_for_hz(MIN_HZ * 1.001).is_ok());
    }

    #[test]
    fn a_refused_rate_says_its_range_with_the_value_short() {
        assert_eq!(
            InvalidRate { hz: 0.0 }.to_string(),
            "rate must be a finite rate in (0, 10000] Hz, got 0"
        );
        assert_eq!(
            rate_rule(1e-300),
            "must be at least 3.171e-9 Hz, one tick in the longest run (315360000 s, ratelab::limits::MAX_DURATION_S), got 1e-300"
        );
        assert!(rate_rule(1e300).ends_with("(0, 10000] Hz, got 1e300"));
        assert!(rate_rule(-1e-300).ends_with("(0, 10000] Hz, got -1e-300"));
    }

    #[test]
    fn rate_changes_are_shared_by_clones() {
        let r = Rate::new(50.0).unwrap();
        let r2 = r.clone();
        r.set_hz(5.0).unwrap();
        assert_eq!(r2.period(), Nanos(200_000_000));
        assert_eq!(r2.hz(), 5.0);
        assert!(r.set_hz(0.0).is_err());
        assert_eq!(r2.hz(), 5.0);
    }

    #[test]
    fn long_waits_wake_for_a_stop() {
        let w = DeadlineWaiter::default();
        let start = Instant::now();
        let far = start + std::time::Duration::from_secs(3600);
        let stop_at = start + std::time::Duration::from_millis(50);
        assert!(!w.wait_until_or(far, &|| Instant::now() >= stop_at));
        let took = start.elapsed();
        assert!(
            took < std::time::Duration::from_millis(500),
            "a stop took {took:?} to notice"
        );
        let near = Instant::now() + std::time::Duration::from_millis(30);
        assert!(w.wait_until_or(near, &|| false));
        assert!(Instant::now() >= near);
    }

    #[test]
    fn next_deadline_keeps_the_grid() {
        let p = Nanos(20);
        assert_eq!(next_deadline(Nanos(100), Nanos(105), p), (Nanos(120), 0));
        assert_eq!(next_deadline(Nanos(100), Nanos(119), p), (Nanos(120), 0));
        // Overran past one deadline: skip it, land on the grid.
        assert_eq!(next_deadline(Nanos(100), Nanos(120), p), (Nanos(140), 1));
        assert_eq!(next_deadline(Nanos(100), Nanos(175), p), (Nanos(180), 3));
    }

    #[test]
    fn a_new_grid_starts_at_its_first_point_at_or_after_the_change() {
        let p = Nanos(20);
        assert_eq!(first_on_grid(Nanos(7), p, Nanos(0)), Nanos(7));
        assert_eq!(first_on_grid(Nanos(7), p, Nanos(7)), Nanos(7));
        assert_eq!(first_on_grid(Nanos(7), p, Nanos(8)), Nanos(27));
        assert_eq!(first_on_grid(Nanos(7), p, Nanos(2005)), Nanos(2007));
        assert_eq!(first_on_grid(Nanos(7), p, Nanos(2027)), Nanos(2027));
        assert_eq!(first_on_grid(Nanos(5), Nanos(0), Nanos(99)), Nanos(5));
    }
}
