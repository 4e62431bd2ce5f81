//! How well a graph's estimator tracks the plant: the state estimate the policy reads
//! against the plant's true state at the same instant, as the estimate's error (RMS, per
//! state component) and its lag (the delay that best lines the estimate up with the truth).
//!
//! A graph has an estimator when the chapter's chain runs through one
//! ([`crate::ids`]; the runtime's `GraphSpec::estimate_topic`): the policy's `state` input is
//! published by a node that is not the sensor (the built-in estimator, a Python filter).
//! At each actuator tick the actuator takes one [`EstimatePoint`]: the newest estimate
//! published on that topic by then (what the policy reads) beside the plant's state at that
//! instant, before the tick's step (what the sensors read then). [`EstimateError`] folds
//! the points as they come, in memory that does not grow with the run.
//!
//! The lag is the shift τ (0 to [`MAX_LAG`], in steps of [`LAG_STEP`]) that minimises the
//! RMS of `estimate(t) − truth(t − τ)`, the truth interpolated linearly between actuator
//! ticks: the cross-correlation alignment used to measure a filter's delay. For the pole
//! angle it is mostly the pipeline's age of data; for the angular velocity a low-pass
//! filter's smoothing adds about 1/(2π·cut-off) on top.

use crate::plant::wrap_angle;
use crate::time::Nanos;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// The state's components, in the order of [`EstimatePoint`]'s arrays: name and unit.
pub const COMPONENTS: [(&str, &str); 4] = [
    ("cart_pos", "m"),
    ("cart_vel", "m/s"),
    ("pole_angle", "rad"),
    ("pole_angvel", "rad/s"),
];
/// Index of the pole angle in [`EstimatePoint`]'s arrays.
pub const POLE_ANGLE: usize = 2;
/// Index of the pole's angular velocity in [`EstimatePoint`]'s arrays.
pub const POLE_ANGVEL: usize = 3;
/// The largest lag searched for (a lag found at it reads "250 ms or more").
pub const MAX_LAG: Nanos = Nanos(250_000_000);
/// The lag search's step.
pub const LAG_STEP: Nanos = Nanos(1_000_000);
/// The lags searched: 0, 1, …, 250 ms.
const LAGS: usize = (MAX_LAG.0 / LAG_STEP.0) as usize + 1;
/// The components whose lag is measured: the pole angle and its angular velocity.
const LAGGED: [usize; 2] = [POLE_ANGLE, POLE_ANGVEL];

/// One actuator tick's estimate beside the truth. Arrays are in [`COMPONENTS`]' order:
/// cart position m, cart velocity m/s, pole angle rad, pole angular velocity rad/s.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimatePoint {
    /// The plant's state at the tick, before its step.
    pub truth: [f64; 4],
    /// The newest estimate published by then: `None` before the first, and when it was
    /// not finite (NaN or ±inf: counted in [`EstimatePoint::nonfinite`] instead).
    pub estimate: Option<[f64; 4]>,
    /// The newest estimate was not finite.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub nonfinite: bool,
}

impl EstimatePoint {
    /// The point of a tick: the plant's state `truth` (in [`COMPONENTS`]' order) and the
    /// newest estimate, if any, an observation `[x, ẋ, cos θ, sin θ, θ̇]` (its angle is
    /// atan2 of the two).
    pub fn new(truth: [f64; 4], estimate: Option<&crate::plant::Observation>) -> EstimatePoint {
        let estimate = estimate.map(|o| {
            let [x, v, cos, sin, w] = o.map(f64::from);
            [x, v, sin.atan2(cos), w]
        });
        let nonfinite = estimate.is_some_and(|e| e.iter().any(|x| !x.is_finite()));
        EstimatePoint {
            truth,
            estimate: estimate.filter(|_| !nonfinite),
            nonfinite,
        }
    }

    /// The estimate's error, `estimate − truth` (the angle's wrapped to [-π, π)), when there
    /// is an estimate.
    pub fn error(&self) -> Option<[f64; 4]> {
        let est = self.estimate?;
        let mut e = [0.0; 4];
        for (i, e) in e.iter_mut().enumerate() {
            *e = est[i] - self.truth[i];
        }
        e[POLE_ANGLE] = wrap_angle(e[POLE_ANGLE]);
        Some(e)
    }
}

/// The folded error of a run's estimates ([`EstimateError::push`] each tick's point, in
/// time order). Its memory is fixed for the actuator's fixed rate: the sums, and the truth
/// of the last [`MAX_LAG`].
#[derive(Clone, Debug, Default)]
pub struct EstimateError {
    /// Ticks folded.
    ticks: u64,
    /// Ticks with a (finite) estimate.
    samples: u64,
    /// Ticks whose newest estimate was not finite.
    nonfinite: u64,
    /// Σ error², per component.
    sum_sq: [f64; 4],
    /// The truth of the lagged components, every tick, over the last [`MAX_LAG`] and one
    /// tick before.
    truth: VecDeque<(Nanos, [f64; 2])>,
    /// Σ (estimate(t) − truth(t − τ))², per lagged component and lag; taken only at ticks
    /// with an estimate whose whole lag window has a truth, so every lag sums over the same
    /// ticks.
    lag_sq: Vec<[f64; LAGS]>,
}

impl EstimateError {
    /// Folds the point taken at run time `t` (after every earlier point).
    pub fn push(&mut self, t: Nanos, p: &EstimatePoint) {
        self.ticks += 1;
        self.nonfinite += u64::from(p.nonfinite);
        // The truth of every tick, estimate or not: the lag interpolates between ticks.
        self.truth.push_back((t, LAGGED.map(|i| p.truth[i])));
        // Keep one truth at or before t − MAX_LAG, for the interpolation.
        while self
            .truth
            .get(1)
            .is_some_and(|(u, _)| t.saturating_sub(*u) >= MAX_LAG)
        {
            self.truth.pop_front();
        }
        let (Some(est), Some(err)) = (p.estimate, p.error()) else {
            return;
        };
        self.samples += 1;
        for (s, e) in self.sum_sq.iter_mut().zip(err) {
            *s += e * e;
        }
        let Some(&(first, _)) = self.truth.front() else {
            return;
        };
        if t < first + MAX_LAG {
            return; // the run is younger than the window
        }
        if self.lag_sq.is_empty() {
            self.lag_sq = vec![[0.0; LAGS]; LAGGED.len()];
        }
        for (k, lag) in (0..LAGS).map(|k| (k, Nanos(LAG_STEP.0 * k as u64))) {
            let truth = self.truth_at(t - lag);
            for (j, &i) in LAGGED.iter().enumerate() {
                let mut e = est[i] - truth[j];
                if i == POLE_ANGLE {
                    e = wrap_angle(e);
                }
                self.lag_sq[j][k] += e * e;
            }
        }
    }

    /// The lagged components' truth at `at` (within the window kept), interpolated
    /// linearly between the ticks around it (the angle along the shorter way round).
    fn truth_at(&self, at: Nanos) -> [f64; 2] {
        let after = self.truth.partition_point(|(u, _)| *u < at);
        let Some(&(t1, v1)) = self.truth.get(after) else {
            return self.truth.back().map_or([0.0; 2], |(_, v)| *v);
        };
        let Some(&(t0, v0)) = after.checked_sub(1).and_then(|b| self.truth.get(b)) else {
            return v1;
        };
        let w = (at - t0).0 as f64 / (t1 - t0).0.max(1) as f64;
        [
            wrap_angle(v0[0] + w * wrap_angle(v1[0] - v0[0])),
            v0[1] + w * (v1[1] - v0[1]),
        ]
    }

    /// The figures so far; `None` before the first tick.
    pub fn figures(&self) -> Option<EstimateFigures> {
        if self.ticks == 0 {
            return None;
        }
        let n = self.samples as f64;
        let rms = (self.samples > 0).then(|| self.sum_sq.map(|s| (s / n).sqrt()));
        let lag = |j: usize| -> Option<f64> {
            let sums = self.lag_sq.get(j)?;
            let (k, _) = sums.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
            // At the bound the true lag may be longer: say so rather than give 250.
            (k + 1 < LAGS).then(|| Nanos(LAG_STEP.0 * k as u64).as_secs_f64() * 1e3)
        };
        Some(EstimateFigures {
            ticks: self.ticks,
            samples: self.samples,
            nonfinite: self.nonfinite,
            rms,
            pole_angle_lag_ms: lag(0),
            pole_angvel_lag_ms: lag(1),
            lag_measured: !self.lag_sq.is_empty(),
        })
    }
}

/// A run's estimator figures with what they are of: `estimator.json` (`--out`), the
/// summary's line.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimateReport {
    /// The estimator node (the publisher of `topic`).
    pub estimator: String,
    /// The topic carrying its estimate (the policy's input).
    pub topic: String,
    /// What the truth is: fixed text, so the file says it without the docs.
    pub truth: String,
    /// The figures.
    #[serde(flatten)]
    pub figures: EstimateFigures,
}

/// [`EstimateReport::truth`]'s text.
pub const TRUTH: &str = "the plant's state at each actuator tick, before its step; the estimate: the newest published on the topic by then, in the policy's queue";

/// What [`EstimateError`] found: the summary's line and `estimator.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EstimateFigures {
    /// Actuator ticks.
    pub ticks: u64,
    /// Actuator ticks with a (finite) estimate.
    pub samples: u64,
    /// Actuator ticks whose newest estimate was not finite (NaN, ±inf), left out.
    pub nonfinite: u64,
    /// RMS error per component, in [`COMPONENTS`]' order and units (m, m/s, rad, rad/s);
    /// `None` without a sample.
    pub rms: Option<[f64; 4]>,
    /// The pole angle's lag, ms (1 ms steps); `None` when not measured or at or beyond
    /// [`MAX_LAG`].
    pub pole_angle_lag_ms: Option<f64>,
    /// The pole angular velocity's lag, ms, likewise.
    pub pole_angvel_lag_ms: Option<f64>,
    /// Whether the lag was measured (estimates for longer than [`MAX_LAG`]).
    pub lag_measured: bool,
}

impl EstimateFigures {
    /// Whether figures that came from elsewhere (another process's report) could be true of
    /// a run of `steps` actuator steps: counts within the steps, finite non-negative errors,
    /// lags within [`MAX_LAG`].
    pub fn plausible(&self, steps: u64) -> bool {
        let lag_ok = |l: Option<f64>| {
            l.is_none_or(|ms| ms.is_finite() && (0.0..MAX_LAG.as_secs_f64() * 1e3).contains(&ms))
        };
        self.ticks <= steps
            && self.samples + self.nonfinite <= self.ticks
            && self
                .rms
                .is_none_or(|r| r.iter().all(|e| e.is_finite() && *e >= 0.0))
            && lag_ok(self.pole_angle_lag_ms)
            && lag_ok(self.pole_angvel_lag_ms)
    }

    /// One line for the summary: `estimate on /state vs the plant (N ticks): RMS error x … mm ·
    /// ẋ … mm/s · θ … mrad · θ̇ … mrad/s; lag θ … ms, θ̇ … ms`.
    pub fn line(&self, topic: &str) -> String {
        let nonfinite = if self.nonfinite > 0 {
            format!(", {} not finite, left out", self.nonfinite)
        } else {
            String::new()
        };
        let Some(rms) = self.rms else {
            return format!(
                "estimate on {topic} vs the plant: no estimate reached the policy's queue in {} ticks{nonfinite}",
                self.ticks
            );
        };
        let [x, v, a, w] = rms.map(|e| e * 1e3);
        let lag = |l: Option<f64>| match (l, self.lag_measured) {
            (Some(ms), _) => format!("{ms:.0} ms"),
            (None, true) => format!("{:.0} ms or more", MAX_LAG.as_secs_f64() * 1e3),
            (None, false) => "not measured (under 250 ms of estimates)".to_string(),
        };
        format!(
            "estimate on {topic} vs the plant ({} ticks{nonfinite}): RMS error x {x:.2} mm · ẋ {v:.1} mm/s · θ {a:.2} mrad · θ̇ {w:.1} mrad/s; lag θ {}, θ̇ {}",
            self.samples,
            lag(self.pole_angle_lag_ms),
            lag(self.pole_angvel_lag_ms),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth truth: x = sin t, θ = 0.1 sin 3t, and their derivatives.
    fn truth(t: f64) -> [f64; 4] {
        [
            t.sin(),
            t.cos(),
            0.1 * (3.0 * t).sin(),
            0.3 * (3.0 * t).cos(),
        ]
    }

    fn run(delay_s: f64, bias: [f64; 4], seconds: f64) -> EstimateFigures {
        let mut e = EstimateError::default();
        let ticks = (seconds * 50.0) as u64;
        for k in 0..ticks {
            let t = Nanos(k * 20_000_000);
            let s = t.as_secs_f64();
            let mut estimate = truth((s - delay_s).max(0.0));
            for (x, b) in estimate.iter_mut().zip(bias) {
                *x += b;
            }
            e.push(
                t,
                &EstimatePoint {
                    truth: truth(s),
                    estimate: Some(estimate),
                    nonfinite: false,
                },
            );
        }
        e.figures().unwrap()
    }

    #[test]
    fn an_exact_estimate_has_no_error_and_no_lag() {
        let f = run(0.0, [0.0; 4], 5.0);
        assert_eq!(f.samples, 250);
        assert_eq!(f.rms, Some([0.0; 4]));
        assert_eq!(f.pole_angle_lag_ms, Some(0.0));
        assert_eq!(f.pole_angvel_lag_ms, Some(0.0));
    }

    #[test]
    fn a_delayed_estimate_is_found_delayed_between_ticks() {
        // 30 ms and 37 ms: on a tick and between two (truth every 20 ms, interpolated).
        for (delay, want) in [(0.030, 30.0), (0.037, 37.0)] {
            let f = run(delay, [0.0; 4], 10.0);
            let (a, w) = (f.pole_angle_lag_ms.unwrap(), f.pole_angvel_lag_ms.unwrap());
            assert!((a - want).abs() <= 1.0, "{delay}: θ lag {a} ms");
            assert!((w - want).abs() <= 1.0, "{delay}: θ̇ lag {w} ms");
            assert!(f.rms.unwrap()[POLE_ANGLE] > 0.0);
        }
    }

    #[test]
    fn a_constant_bias_is_the_rms_error() {
        let f = run(0.0, [0.01, 0.0, -0.002, 0.0], 2.0);
        let rms = f.rms.unwrap();
        assert!((rms[0] - 0.01).abs() < 1e-12);
        assert!((rms[POLE_ANGLE] - 0.002).abs() < 1e-12);
        assert_eq!(rms[1], 0.0);
    }

    #[test]
    fn a_lag_beyond_the_search_or_a_short_run_is_said_so() {
        let f = run(0.4, [0.0; 4], 10.0);
        assert_eq!(f.pole_angle_lag_ms, None);
        assert!(f.lag_measured);
        assert!(
            f.line("/state").contains("lag θ 250 ms or more"),
            "{}",
            f.line("/state")
        );
        let short = run(0.0, [0.0; 4], 0.2);
        assert!(!short.lag_measured);
        assert!(short.line("/state").contains("not measured"));
    }

    /// Ticks without an estimate still give the truth (the lag interpolates over every
    /// tick); a non-finite estimate is counted and left out, never a NaN figure.
    #[test]
    fn gaps_and_non_finite_estimates_leave_the_figures_true() {
        let mut e = EstimateError::default();
        for k in 0..500u64 {
            let t = Nanos(k * 20_000_000);
            let s = t.as_secs_f64();
            let estimate = match k % 4 {
                0 => Some(&[f32::NAN; 5]),
                1 => None,
                _ => Some(&[0.0; 5]),
            };
            let mut p = EstimatePoint::new(truth(s), estimate);
            if let (Some(est), 2 | 3) = (&mut p.estimate, k % 4) {
                *est = truth(s - 0.03); // 30 ms late
            }
            e.push(t, &p);
        }
        let f = e.figures().unwrap();
        assert_eq!((f.ticks, f.samples, f.nonfinite), (500, 250, 125));
        assert!(f.rms.unwrap().iter().all(|x| x.is_finite()));
        assert_eq!(f.pole_angle_lag_ms, Some(30.0));
        assert!(f.plausible(500) && !f.plausible(499));
        assert!(f
            .line("/state")
            .contains("(250 ticks, 125 not finite, left out)"));
        let none = EstimateError::default();
        assert_eq!(none.figures(), None);
        let mut empty = EstimateError::default();
        empty.push(Nanos(0), &EstimatePoint::new([0.0; 4], None));
        let f = empty.figures().unwrap();
        assert_eq!(f.rms, None);
        assert!(f
            .line("/x")
            .contains("no estimate reached the policy's queue in 1 ticks"));
    }

    /// The truth interpolated across ±π goes the short way round.
    #[test]
    fn the_angle_is_interpolated_the_short_way_round() {
        let mut e = EstimateError::default();
        let at = |theta: f64| [0.0, 0.0, wrap_angle(theta), 0.0];
        let pi = std::f64::consts::PI;
        e.truth.push_back((Nanos(0), [wrap_angle(pi - 0.01), 0.0]));
        e.truth.push_back((Nanos(20), [wrap_angle(pi + 0.01), 0.0]));
        let mid = e.truth_at(Nanos(10))[0];
        assert!((wrap_angle(mid - pi)).abs() < 1e-9, "{mid}");
        let p = EstimatePoint::new(at(pi + 0.01), None);
        assert_eq!(p.error(), None);
    }

    #[test]
    fn memory_stays_flat() {
        let mut e = EstimateError::default();
        let p = EstimatePoint {
            truth: [0.0; 4],
            estimate: Some([0.0; 4]),
            nonfinite: false,
        };
        for k in 0..100_000u64 {
            e.push(Nanos(k * 20_000_000), &p);
        }
        assert!(e.truth.len() <= 14, "{}", e.truth.len());
    }

    #[test]
    fn the_line_gives_units() {
        let f = run(0.0, [0.001, -0.002, 0.0005, 0.0], 3.0);
        assert_eq!(
            f.line("/state"),
            "estimate on /state vs the plant (150 ticks): RMS error x 1.00 mm · ẋ 2.0 mm/s · θ 0.50 mrad · θ̇ 0.0 mrad/s; lag θ 0 ms, θ̇ 0 ms"
        );
    }
}
