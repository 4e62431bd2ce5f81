//! A message type of the program's own — a cart position setpoint — and a node kind that
//! publishes it, registered by `examples/custom_message.rs` (and usable by any program
//! that includes this file). One definition each: adding a message type is this `impl
//! Message` plus `register::<Setpoint>()`.

use ratelab::graph::registry::{register, NodeContext, RustNode};
use ratelab::msg::{self, Field, Message};
use ratelab::Nanos;
use serde::{Deserialize, Serialize};

/// Where the cart should be, m: what a planner tells a controller.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Setpoint {
    /// Cart position to hold, m.
    pub cart_pos_m: f64,
}

impl Message for Setpoint {
    const NAME: &'static str = "setpoint";
    const CLASS: &'static str = "Setpoint";
    const DOC: &'static str = "Where the cart should be.";
    const FIELDS: &'static [Field] = &[Field::new("cart_pos_m", "m", "cart position to hold")];
    fn to_fields(&self) -> Vec<f64> {
        vec![self.cart_pos_m]
    }
    fn from_fields(f: &[f64]) -> Self {
        Setpoint { cart_pos_m: f[0] }
    }
    // No ROS 2 type: `--ros2` refuses a graph that carries it, in one line.
}

/// A square wave between -amplitude_m and +amplitude_m, switching every half period_s: a
/// node with no input, publishing on every tick (its data begins at its tick).
pub struct SquareSetpoint {
    amplitude_m: f64,
    half_period_ns: u64,
}

impl RustNode for SquareSetpoint {
    type Input = ();
    type Output = Setpoint;

    fn tick(&mut self, now: Nanos, _: ()) -> Option<Setpoint> {
        let half = now.0 / self.half_period_ns;
        let sign = if half % 2 == 0 { 1.0 } else { -1.0 };
        Some(Setpoint {
            cart_pos_m: sign * self.amplitude_m,
        })
    }
}

/// Register the `setpoint` message type and the `square_setpoint` kind (`params`:
/// `amplitude_m`, default 0.3; `period_s`, default 8).
pub fn register_setpoint() {
    msg::register::<Setpoint>().expect("'setpoint' is free");
    register("square_setpoint", |cx: &NodeContext<'_>| {
        let period_s = cx.param_f64("period_s", 8.0)?;
        if !(period_s > 0.0 && period_s <= 3600.0) {
            return Err(format!(
                "node '{}': params.period_s must be in (0, 3600]",
                cx.name
            ));
        }
        Ok(SquareSetpoint {
            amplitude_m: cx.param_f64("amplitude_m", 0.3)?,
            half_period_ns: (period_s * 1e9 / 2.0) as u64,
        })
    })
    .expect("'square_setpoint' is free");
}
