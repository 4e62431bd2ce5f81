//! The **policy** kind: runs the run's brain (`--policy`) on the newest state (nothing
//! before the first) and publishes the force, `command × GEAR_N` newtons, with the state's
//! origin.

use crate::graph::kind::{
    publisher, typed, BuildContext, Code, KindDef, Params, Plant, Ports, Work,
};
use crate::plant::GEAR_N;
use crate::policy::BrainSlot;
use ratelab_core::msg::{ForceMsg, Message, StateMsg};
use ratelab_core::node::Flow;
use ratelab_core::publisher::Publisher;
use ratelab_core::time::Nanos;
use ratelab_core::topic::Subscription;
use std::sync::Arc;

/// The kind: `state` in, `force` out, the brain between.
pub fn def() -> KindDef {
    KindDef {
        name: "policy",
        doc: "runs the --policy brain on the newest state and publishes a force",
        ports: Ports::Fixed {
            inputs: vec![&[StateMsg::TYPE]],
            outputs: vec![&[ForceMsg::TYPE]],
        },
        plant: Plant::None,
        code: Code::BuiltIn,
        params: Params::Numbers(&[]),
        uses_brain: true,
        make: Box::new(|cx: &mut BuildContext<'_>| {
            Ok(Box::new(PolicyNode {
                name: cx.name.into(),
                brain: cx.brain.clone(),
                input: typed(cx.inputs.first())?,
                output: publisher(cx.outputs.first(), cx.outbox)?,
            }) as Box<dyn Work>)
        }),
    }
}

/// A policy node's state.
pub struct PolicyNode {
    /// The node's name: what its brain writes is stamped with it ([`ratelab_core::textlog`]).
    pub name: std::sync::Arc<str>,
    /// The brain.
    pub brain: BrainSlot,
    /// Input.
    pub input: Arc<Subscription<StateMsg>>,
    /// Output.
    pub output: Publisher<ForceMsg>,
}

impl Work for PolicyNode {
    // Nothing kept between ticks (the brain is the graph's, captured apart).
    fn save(&self) -> Option<ratelab_core::node::NodeState> {
        Some(Box::new(()))
    }
    fn load(&mut self, state: &ratelab_core::node::NodeState) -> bool {
        state.is::<()>()
    }
    fn tick(&mut self, now: Nanos) -> Flow {
        let Some(msg) = self.input.read(now) else {
            return Flow::Continue; // nothing sensed yet
        };
        let action = {
            let _stamp = ratelab_core::textlog::enter(&self.name, now);
            self.brain.lock().act(&msg.data)
        };
        let force = ForceMsg {
            newtons: f64::from(action[0]) * GEAR_N,
        };
        self.output
            .publish(force, now, msg.origin_stamp.or(Some(msg.stamp)));
        Flow::Continue
    }
}
