//! The PD controller both node-kind examples register as `kind = "pd"`
//! (`examples/custom_node.rs`, `examples/custom_node_processes.rs`).

use ratelab::graph::registry::{register, Held, NodeContext, RustNode, Stamped};
use ratelab::msg::{ForceMsg, StateMsg};
use ratelab::plant::GEAR_N;
use ratelab::Nanos;

/// A PD controller on the pole angle and the cart position, from the full state.
pub struct Pd {
    kp_angle: f64,
    kd_angle: f64,
    kp_pos: f64,
    kd_pos: f64,
}

impl RustNode for Pd {
    /// The newest state, every tick (`Held`: a zero-order hold on its input, as the
    /// chapter's policy node reads the latest message every tick; `StateMsg` alone would
    /// give each new state once).
    type Input = Held<StateMsg>;
    type Output = ForceMsg;

    fn tick(&mut self, _now: Nanos, input: Option<&Stamped<StateMsg>>) -> Option<ForceMsg> {
        let [x, x_dot, cos_t, sin_t, theta_dot] = input?.data.map(f64::from);
        let theta = sin_t.atan2(cos_t);
        let u = self.kp_angle * theta
            + self.kd_angle * theta_dot
            + self.kp_pos * x
            + self.kd_pos * x_dot;
        // The chapter's action: float32 in [-1, 1], times the motor's gear.
        let command = u.clamp(-1.0, 1.0) as f32;
        Some(ForceMsg {
            newtons: f64::from(command) * GEAR_N,
        })
    }
}

/// Register [`Pd`] as `kind = "pd"`; its gains are the graph file's `params` (`kp_angle`,
/// `kd_angle`, `kp_pos`, `kd_pos`; defaults the chapter's balancer's: 10, 2, 0.4, 0.8).
pub fn register_pd() {
    register("pd", |cx: &NodeContext<'_>| {
        Ok(Pd {
            kp_angle: cx.param_f64("kp_angle", 10.0)?,
            kd_angle: cx.param_f64("kd_angle", 2.0)?,
            kp_pos: cx.param_f64("kp_pos", 0.4)?,
            kd_pos: cx.param_f64("kd_pos", 0.8)?,
        })
    })
    .expect("'pd' is free");
}
