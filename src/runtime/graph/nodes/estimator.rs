//! The **estimator** kind: reads the newest position measurement, updates the
//! [`VelocityFilter`], publishes the state estimate every tick. Before its first
//! measurement it publishes nothing; its estimate carries the origin of the newest
//! measurement it used.

use crate::graph::estimator::VelocityFilter;
use crate::graph::kind::{Code, KindDef, ParamDef, Params};
use ratelab_core::msg::{PositionMsg, StateMsg};
use ratelab_core::node::NodeState;
use ratelab_core::ports::{Held, RustNode, Stamped};
use ratelab_core::rate::MAX_HZ;
use ratelab_core::time::Nanos;

/// Its parameter: the low-pass cut-off.
pub const PARAMS: &[ParamDef] = &[ParamDef {
    name: "cutoff_hz",
    unit: "Hz",
    doc: "cut-off of the first-order low-pass on the differentiated velocities",
    default: 10.0,
    min: 0.01,
    max: MAX_HZ,
}];

/// The kind: `position` in, `state` out.
pub fn def() -> KindDef {
    KindDef {
        doc: "turns position measurements into a state estimate (differences, low-pass)",
        code: Code::BuiltIn,
        params: Params::Numbers(PARAMS),
        ..KindDef::of("estimator", |cx| {
            Ok(Estimator {
                filter: VelocityFilter::new(cx.node.param_f64("cutoff_hz", 10.0)?),
                last_seq: None,
            })
        })
    }
}

/// An estimator node.
pub struct Estimator {
    /// The filter.
    pub filter: VelocityFilter,
    /// `seq` of the last measurement fed to the filter.
    pub last_seq: Option<u64>,
}

impl RustNode for Estimator {
    type Input = Held<PositionMsg>;
    type Output = StateMsg;

    fn tick(&mut self, _now: Nanos, position: Option<&Stamped<PositionMsg>>) -> Option<StateMsg> {
        // Once measured, an estimate every tick (its origin the newest measurement's).
        let msg = position?;
        if self.last_seq != Some(msg.seq) {
            self.last_seq = Some(msg.seq);
            self.filter.update(msg.stamp, msg.data);
        }
        Some(self.filter.estimate())
    }

    fn save(&self) -> Option<NodeState> {
        Some(Box::new((self.filter.clone(), self.last_seq)))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        let Some((filter, last_seq)) = state.downcast_ref::<(VelocityFilter, Option<u64>)>() else {
            return false;
        };
        self.filter.clone_from(filter);
        self.last_seq = *last_seq;
        true
    }
}
