//! Pacing a run against the wall clock: the [`Pacer`], which the drive loop's policies ask
//! before each instant (the headless run offered to ROS 2 at ×1, the lab at its speed) and
//! the launcher asks for its lockstep's horizon.

use super::{Course, DrivePolicy, Pace, Unit, MAX_PACING_SLEEP};
use ratelab_core::time::Nanos;
use std::convert::Infallible;
use std::time::{Duration, Instant};

/// Keeps pace with the wall clock at a speed: run time `anchor` is the wall instant the
/// pacer was anchored at, and run time passes `speed` times as fast as the wall's (`None`:
/// as fast as the instants run). The headless run offered to ROS 2 runs at ×1; the lab at
/// the speed its keys chose, anchored again when paused, resumed or sped up; a launch the
/// lab follows keeps its lockstep's horizon within the run time due
/// ([`Pacer::run_time_now`]).
#[derive(Clone, Copy, Debug)]
pub struct Pacer {
    anchor_run: Nanos,
    anchor_wall: Instant,
    speed: Option<f64>,
}

impl Pacer {
    /// Run time `at` is now on the wall; run time then passes at `speed` (× the wall's;
    /// `None`: no pacing). A speed that is not finite and positive paces nothing.
    pub fn new(at: Nanos, speed: Option<f64>) -> Pacer {
        Pacer {
            anchor_run: at,
            anchor_wall: Instant::now(),
            speed: speed.filter(|x| x.is_finite() && *x > 0.0),
        }
    }

    /// Anchor again: run time `at` is now (after a pause, a seek or a change of speed).
    pub fn anchor(&mut self, at: Nanos) {
        self.anchor_run = at;
        self.anchor_wall = Instant::now();
    }

    /// A new speed from run time `at`, now ([`Pacer::new`]'s rule).
    pub fn set_speed(&mut self, at: Nanos, speed: Option<f64>) {
        *self = Pacer::new(at, speed);
    }

    /// The wall instant at which run time `t` is due (`None`: unpaced).
    pub fn due(&self, t: Nanos) -> Option<Instant> {
        let x = self.speed?;
        let ahead_ns = t.saturating_sub(self.anchor_run).0 as f64 / x;
        Some(self.anchor_wall + Duration::from_nanos(ahead_ns as u64))
    }

    /// The run time due now: how far the wall clock has come since the anchor, at the
    /// speed (`None`: unpaced, nothing holds the run back).
    pub fn run_time_now(&self) -> Option<Nanos> {
        let x = self.speed?;
        let ahead_ns = self.anchor_wall.elapsed().as_secs_f64() * x * 1e9;
        Some(
            self.anchor_run
                .saturating_add(Nanos(ahead_ns.min(u64::MAX as f64) as u64)),
        )
    }

    /// Run `t` now when it is due, else sleep until it is (at most [`MAX_PACING_SLEEP`]).
    pub fn pace(&self, t: Nanos) -> Pace {
        match self.due(t) {
            Some(due) => match due.checked_duration_since(Instant::now()) {
                Some(wait) if !wait.is_zero() => Pace::Sleep(wait.min(MAX_PACING_SLEEP)),
                _ => Pace::Now,
            },
            None => Pace::Now,
        }
    }
}

/// The headless run's policy when offered to ROS 2: every unit when it is due, nothing
/// taken in between.
impl<U: Unit, C: Course<U> + ?Sized> DrivePolicy<U, C> for Pacer {
    type Error = Infallible;

    fn pace(&mut self, t: Nanos) -> Pace {
        Pacer::pace(self, t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn secs(s: f64) -> Nanos {
        Nanos((s * 1e9).round() as u64)
    }

    #[test]
    fn the_pacer_runs_what_is_due_and_sleeps_at_most_the_cap_for_the_rest() {
        let p = Pacer::new(secs(1.0), Some(2.0));
        assert_eq!(p.pace(secs(0.5)), Pace::Now, "behind: now");
        assert_eq!(p.pace(secs(1.0)), Pace::Now);
        match p.pace(secs(1.004)) {
            Pace::Sleep(d) => assert!(d <= Duration::from_millis(2), "4 ms at ×2 is 2 ms: {d:?}"),
            Pace::Now => panic!("not yet due"),
        }
        assert_eq!(p.pace(secs(60.0)), Pace::Sleep(MAX_PACING_SLEEP));
        let now = p.run_time_now().unwrap();
        assert!(now >= secs(1.0) && now < secs(3.0), "{now:?}");
        assert_eq!(Pacer::new(Nanos::ZERO, None).run_time_now(), None);
        let due = p.due(secs(3.0)).unwrap();
        let ahead = due.duration_since(p.anchor_wall);
        assert_eq!(ahead, Duration::from_secs(1), "2 s of run time at ×2");
        for speed in [
            None,
            Some(0.0),
            Some(-1.0),
            Some(f64::NAN),
            Some(f64::INFINITY),
        ] {
            let p = Pacer::new(Nanos::ZERO, speed);
            assert_eq!(p.pace(secs(1e6)), Pace::Now, "{speed:?}");
        }
    }
}
