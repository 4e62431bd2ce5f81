//! The **safety** kind: clamps the newest force to ±`max_force_n` and republishes it, with
//! its origin.

use crate::graph::kind::{
    publisher, typed, BuildContext, Code, KindDef, ParamDef, Params, Plant, Ports, Work,
};
use crate::plant::GEAR_N;
use ratelab_core::msg::{ForceMsg, Message};
use ratelab_core::node::Flow;
use ratelab_core::publisher::Publisher;
use ratelab_core::time::Nanos;
use ratelab_core::topic::Subscription;
use std::sync::Arc;

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
        name: "safety",
        doc: "clamps the newest force to ±max_force_n and passes it on",
        ports: Ports::Fixed {
            inputs: vec![&[ForceMsg::TYPE]],
            outputs: vec![&[ForceMsg::TYPE]],
        },
        plant: Plant::None,
        code: Code::BuiltIn,
        params: Params::Numbers(PARAMS),
        uses_brain: false,
        make: Box::new(|cx: &mut BuildContext<'_>| {
            Ok(Box::new(Safety {
                input: typed(cx.inputs.first())?,
                output: publisher(cx.outputs.first(), cx.outbox)?,
                max_force_n: cx.param_f64("max_force_n", GEAR_N)?,
            }) as Box<dyn Work>)
        }),
    }
}

/// A safety node's state.
pub struct Safety {
    /// Input.
    pub input: Arc<Subscription<ForceMsg>>,
    /// Output.
    pub output: Publisher<ForceMsg>,
    /// Largest magnitude passed on, N.
    pub max_force_n: f64,
}

impl Work for Safety {
    // Nothing kept between ticks (the brain is the graph's, captured apart).
    fn save(&self) -> Option<ratelab_core::node::NodeState> {
        Some(Box::new(()))
    }
    fn load(&mut self, state: &ratelab_core::node::NodeState) -> bool {
        state.is::<()>()
    }
    fn tick(&mut self, now: Nanos) -> Flow {
        if let Some(msg) = self.input.read(now) {
            let newtons = msg.data.newtons.clamp(-self.max_force_n, self.max_force_n);
            self.output
                .publish(ForceMsg { newtons }, now, msg.origin_stamp);
        }
        Flow::Continue
    }
}
