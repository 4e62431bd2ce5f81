//! The **safety** node: clamps the newest force to ±`max_force_n` and republishes it, with
//! its origin.

use crate::msg::ForceMsg;
use crate::node::Flow;
use crate::publisher::Publisher;
use crate::time::Nanos;
use crate::topic::Topic;
use std::sync::Arc;

/// A safety node's state.
pub struct Safety {
    /// Input.
    pub input: Arc<Topic<ForceMsg>>,
    /// Output.
    pub output: Publisher<ForceMsg>,
    /// Largest magnitude passed on, N.
    pub max_force_n: f64,
}

impl Safety {
    /// One tick at `now`.
    pub fn tick(&mut self, now: Nanos) -> Flow {
        if let Some(msg) = self.input.read(now) {
            let newtons = msg.data.newtons.clamp(-self.max_force_n, self.max_force_n);
            self.output
                .publish(ForceMsg { newtons }, now, msg.origin_stamp);
        }
        Flow::Continue
    }
}
