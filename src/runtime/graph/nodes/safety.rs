//! The **safety** kind: clamps the newest force (the last one again when nothing new came)
//! to ±`max_force_n` and republishes it, with its origin (as every node passes an origin
//! on, [`ratelab_core::ports::RustNode::tick`]: a force that has none, a Python node's
//! before its first input, counts from its own stamp; before issue 71's one node trait the
//! safety node passed on none).

use crate::graph::kind::{Code, KindDef, ParamDef, Params};
use crate::plant::GEAR_N;
use ratelab_core::msg::ForceMsg;
use ratelab_core::node::NodeState;
use ratelab_core::ports::{Held, RustNode, Stamped};
use ratelab_core::time::Nanos;

/// Its parameter: the clamp.
pub const PARAMS: &[ParamDef] = &[ParamDef {
    name: "max_force_n",
    unit: "N",
    doc: "the largest force magnitude passed on",
    default: GEAR_N,
    min: 0.0,
    max: GEAR_N,
}];

/// The kind: `force` in, `force` out.
pub fn def() -> KindDef {
    KindDef {
        doc: "clamps the newest force to ±max_force_n and passes it on",
        code: Code::BuiltIn,
        params: Params::Numbers(PARAMS),
        ..KindDef::of("safety", |cx| {
            Ok(Safety {
                max_force_n: cx.node.param_f64("max_force_n", GEAR_N)?,
            })
        })
    }
}

/// A safety node.
pub struct Safety {
    /// Largest magnitude passed on, N.
    pub max_force_n: f64,
}

impl RustNode for Safety {
    type Input = Held<ForceMsg>;
    type Output = ForceMsg;

    fn tick(&mut self, _now: Nanos, force: Option<&Stamped<ForceMsg>>) -> Option<ForceMsg> {
        let newtons = force?.data.newtons;
        Some(ForceMsg {
            newtons: newtons.clamp(-self.max_force_n, self.max_force_n),
        })
    }

    // Nothing kept between ticks.
    fn save(&self) -> Option<NodeState> {
        Some(Box::new(()))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        state.is::<()>()
    }
}
