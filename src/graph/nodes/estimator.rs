//! The **estimator**: reads the newest position measurement, updates the
//! [`VelocityFilter`], publishes the state estimate every tick. Before its first
//! measurement it publishes nothing; its estimate carries the origin of the newest
//! measurement it used.

use crate::graph::estimator::VelocityFilter;
use crate::msg::{PositionMsg, StateMsg};
use crate::node::Flow;
use crate::publisher::Publisher;
use crate::time::Nanos;
use crate::topic::Topic;
use std::sync::Arc;

/// An estimator's state.
pub struct Estimator {
    /// Input.
    pub input: Arc<Topic<PositionMsg>>,
    /// Output.
    pub output: Publisher<StateMsg>,
    /// The filter.
    pub filter: VelocityFilter,
    /// `seq` of the last measurement fed to the filter.
    pub last_seq: Option<u64>,
    /// Origin of the newest measurement used.
    pub origin: Option<Nanos>,
}

impl Estimator {
    /// One tick at `now`.
    pub fn tick(&mut self, now: Nanos) -> Flow {
        if let Some(msg) = self.input.read(now) {
            if self.last_seq != Some(msg.seq) {
                self.last_seq = Some(msg.seq);
                self.origin = msg.origin_stamp.or(Some(msg.stamp));
                self.filter.update(msg.stamp, msg.data);
            }
            self.output
                .publish(self.filter.estimate(), now, self.origin);
        }
        Flow::Continue
    }
}
