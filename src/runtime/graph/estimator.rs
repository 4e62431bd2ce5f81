//! The estimator's filter: the full state from position measurements.
//!
//! Velocities come from a finite difference of the two newest measurements, over the time
//! between their *sensor* stamps (not the estimator's ticks, so a slow estimator still
//! divides by the true interval):
//! `v_raw = (p_k − p_{k−1}) / (t_k − t_{k−1})`,
//! smoothed by a first-order low-pass (an RC filter discretized with the same interval):
//! `τ = 1 / (2π f_c)`, `α = Δt / (τ + Δt)`, `v ← v + α (v_raw − v)`.
//! The first measurement gives zero velocities (nothing to difference yet). The pole angle is
//! unwrapped across ±π before differencing.
//!
//! Lag: for a velocity that changes slowly the smoothed value trails the raw one by about τ
//! (8 ms at the shipped 20 Hz cut-off), on top of the half-interval a backward difference
//! already lags. A learner sees both in the estimator graph's sense→act latency and in the
//! pole's wobble.

use ratelab_core::msg::{PositionMsg, StateMsg};
use ratelab_core::time::Nanos;
use std::f64::consts::PI;

/// The filter's state between measurements.
#[derive(Clone, Debug)]
pub struct VelocityFilter {
    tau_s: f64,
    last: Option<(Nanos, PositionMsg)>,
    cart_vel: f64,
    pole_angvel: f64,
}

impl VelocityFilter {
    /// A filter with a low-pass cut-off of `cutoff_hz` (> 0).
    pub fn new(cutoff_hz: f64) -> Self {
        Self {
            tau_s: 1.0 / (2.0 * PI * cutoff_hz),
            last: None,
            cart_vel: 0.0,
            pole_angvel: 0.0,
        }
    }

    /// Feed the measurement `m` stamped `t` (newer than the previous one); returns the
    /// state estimate `[x, ẋ, cos θ, sin θ, θ̇]` as the chapter's `float32[5]`.
    /// A measurement not newer than the last is ignored (the estimate is unchanged).
    pub fn update(&mut self, t: Nanos, m: PositionMsg) -> StateMsg {
        match self.last {
            None => self.last = Some((t, m)),
            Some((t0, m0)) if t > t0 => {
                let dt = (t - t0).as_secs_f64();
                let alpha = dt / (self.tau_s + dt);
                let raw_x = (m.cart_pos_m - m0.cart_pos_m) / dt;
                let mut dtheta = m.pole_angle_rad - m0.pole_angle_rad;
                if dtheta > PI {
                    dtheta -= 2.0 * PI;
                } else if dtheta < -PI {
                    dtheta += 2.0 * PI;
                }
                let raw_theta = dtheta / dt;
                self.cart_vel += alpha * (raw_x - self.cart_vel);
                self.pole_angvel += alpha * (raw_theta - self.pole_angvel);
                self.last = Some((t, m));
            }
            Some(_) => {}
        }
        self.estimate()
    }

    /// The current estimate (zeros before the first measurement).
    pub fn estimate(&self) -> StateMsg {
        let (x, theta) = self
            .last
            .map_or((0.0, 0.0), |(_, m)| (m.cart_pos_m, m.pole_angle_rad));
        [
            x as f32,
            self.cart_vel as f32,
            theta.cos() as f32,
            theta.sin() as f32,
            self.pole_angvel as f32,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(x: f64, th: f64) -> PositionMsg {
        PositionMsg {
            cart_pos_m: x,
            pole_angle_rad: th,
        }
    }

    #[test]
    fn hand_computed_steps() {
        // f_c = 1/(2π) Hz → τ = 1 s. Measurements 0.1 s apart: α = 0.1 / 1.1.
        let mut f = VelocityFilter::new(1.0 / (2.0 * PI));
        let s = f.update(Nanos(0), m(0.0, 0.0));
        assert_eq!(s[1], 0.0);
        // Cart moves 0.1 m in 0.1 s: raw 1 m/s; v = α·1 = 1/11.
        let s = f.update(Nanos(100_000_000), m(0.1, 0.0));
        assert!((f64::from(s[1]) - 1.0 / 11.0).abs() < 1e-6, "{s:?}");
        // Again 1 m/s: v = 1/11 + α(1 − 1/11) = 1/11 + (1/11)(10/11) = 21/121.
        let s = f.update(Nanos(200_000_000), m(0.2, 0.0));
        assert!((f64::from(s[1]) - 21.0 / 121.0).abs() < 1e-6, "{s:?}");
        assert!((f64::from(s[0]) - 0.2).abs() < 1e-7);
        // A stale measurement changes nothing.
        assert_eq!(f.update(Nanos(200_000_000), m(9.0, 0.0)), s);
    }

    #[test]
    fn angle_is_unwrapped_across_pi() {
        let mut f = VelocityFilter::new(1e6); // τ ≈ 0: raw differences pass through
        f.update(Nanos(0), m(0.0, PI - 0.01));
        let s = f.update(Nanos(10_000_000), m(0.0, -PI + 0.01));
        // +0.02 rad in 10 ms = +2 rad/s, not −628.
        assert!((f64::from(s[4]) - 2.0).abs() < 1e-3, "{s:?}");
    }
}
