//! The **policy** kind: runs the run's brain (`--policy`) on the newest state (the last one
//! again when nothing new came; nothing before the first) and publishes the force,
//! `command × GEAR_N` newtons, with the state's origin.

use crate::graph::kind::{Code, KindDef, Params};
use crate::plant::GEAR_N;
use crate::policy::BrainSlot;
use ratelab_core::msg::{ForceMsg, StateMsg};
use ratelab_core::node::NodeState;
use ratelab_core::ports::{Held, RustNode, Stamped};
use ratelab_core::time::Nanos;

/// The kind: `state` in, `force` out, the brain between.
pub fn def() -> KindDef {
    KindDef {
        doc: "runs the --policy brain on the newest state and publishes a force",
        code: Code::BuiltIn,
        params: Params::Numbers(&[]),
        uses_brain: true,
        ..KindDef::of("policy", |cx| {
            Ok(PolicyNode {
                name: cx.node.name.into(),
                brain: cx.run.brain.clone(),
            })
        })
    }
}

/// A policy node.
pub struct PolicyNode {
    /// The node's name: what its brain writes is stamped with it ([`ratelab_core::textlog`]).
    pub name: std::sync::Arc<str>,
    /// The brain.
    pub brain: BrainSlot,
}

impl RustNode for PolicyNode {
    type Input = Held<StateMsg>;
    type Output = ForceMsg;

    fn tick(&mut self, now: Nanos, state: Option<&Stamped<StateMsg>>) -> Option<ForceMsg> {
        let msg = state?; // nothing sensed yet
        let action = {
            let _stamp = ratelab_core::textlog::enter(&self.name, now);
            self.brain.lock().act(&msg.data)
        };
        Some(ForceMsg {
            newtons: f64::from(action[0]) * GEAR_N,
        })
    }

    // Nothing kept between ticks (the brain is the graph's, captured apart).
    fn save(&self) -> Option<NodeState> {
        Some(Box::new(()))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        state.is::<()>()
    }
}
