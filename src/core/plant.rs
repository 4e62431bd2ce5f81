//! The plant's facts the runtime's parts share, apart from the MuJoCo model that simulates it
//! (`ratelab::plant`): the chapter's cartpole's observation and action widths, its step
//! period, its motor's gear and its fall limits.

use crate::time::Nanos;

/// Observation width: `[cart_pos, cart_vel, cos θ, sin θ, pole_angvel]`.
pub const OBS_DIM: usize = 5;
/// Action width: `[push]`, in [-1, 1].
pub const ACT_DIM: usize = 1;
/// An observation, float32 as the course's env returns it.
pub type Observation = [f32; OBS_DIM];
/// An action, float32; the plant clips it to [-1, 1].
pub type Action = [f32; ACT_DIM];

/// Physics steps per plant step (the action is held for this many).
pub const FRAME_SKIP: usize = 2;
/// The plant's step period (the actuator's period): 2 × 10 ms physics steps.
pub const CONTROL_PERIOD: Nanos = Nanos(20_000_000);
/// The actuator's rate, Hz: one plant step per tick, so it is fixed at 1 / [`CONTROL_PERIOD`]
/// (the chapter's 50 Hz control step; a graph cannot change it).
pub const ACTUATOR_HZ: f64 = 50.0;
/// The motor's gear: a force command of 1 is this many newtons (`cartpole.xml`, gear 10).
pub const GEAR_N: f64 = 10.0;
/// Fall limit on |θ|, rad (≈ 12°).
pub const THETA_LIMIT_RAD: f64 = 0.2095;
/// Fall limit on |cart_pos|, m.
pub const CART_LIMIT_M: f64 = 2.4;
/// Half-width of the uniform reset draws.
pub const RESET_NOISE: f64 = 0.05;

/// θ wrapped to [-π, π).
pub fn wrap_angle(theta: f64) -> f64 {
    use std::f64::consts::PI;
    (theta + PI).rem_euclid(2.0 * PI) - PI
}
