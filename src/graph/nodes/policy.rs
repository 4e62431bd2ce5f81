//! The **policy**: runs the brain on the newest state (nothing before the first) and
//! publishes the force, `command × GEAR_N` newtons, with the state's origin.

use crate::msg::{ForceMsg, StateMsg};
use crate::node::Flow;
use crate::plant::GEAR_N;
use crate::policy::BrainSlot;
use crate::publisher::Publisher;
use crate::time::Nanos;
use crate::topic::Topic;
use std::sync::Arc;

/// A policy node's state.
pub struct PolicyNode {
    /// The brain.
    pub brain: BrainSlot,
    /// Input.
    pub input: Arc<Topic<StateMsg>>,
    /// Output.
    pub output: Publisher<ForceMsg>,
}

impl PolicyNode {
    /// One tick at `now`.
    pub fn tick(&mut self, now: Nanos) -> Flow {
        let Some(msg) = self.input.read(now) else {
            return Flow::Continue; // nothing sensed yet
        };
        let action = self.brain.lock().act(&msg.data);
        let force = ForceMsg {
            newtons: f64::from(action[0]) * GEAR_N,
        };
        self.output
            .publish(force, now, msg.origin_stamp.or(Some(msg.stamp)));
        Flow::Continue
    }
}
