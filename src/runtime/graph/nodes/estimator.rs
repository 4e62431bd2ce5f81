//! The **estimator** kind: reads the newest position measurement, updates the
//! [`VelocityFilter`], publishes the state estimate every tick. Before its first
//! measurement it publishes nothing; its estimate carries the origin of the newest
//! measurement it used.

use crate::graph::estimator::VelocityFilter;
use crate::graph::kind::{
    publisher, typed, BuildContext, Code, KindDef, ParamDef, Params, Plant, Ports, Work,
};
use ratelab_core::msg::{Message, PositionMsg, StateMsg};
use ratelab_core::node::Flow;
use ratelab_core::publisher::Publisher;
use ratelab_core::rate::MAX_HZ;
use ratelab_core::time::Nanos;
use ratelab_core::topic::Subscription;
use std::sync::Arc;

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
        name: "estimator",
        doc: "turns position measurements into a state estimate (differences, low-pass)",
        ports: Ports::Fixed {
            inputs: vec![&[PositionMsg::TYPE]],
            outputs: vec![&[StateMsg::TYPE]],
        },
        plant: Plant::None,
        code: Code::BuiltIn,
        params: Params::Numbers(PARAMS),
        uses_brain: false,
        make: Box::new(|cx: &mut BuildContext<'_>| {
            Ok(Box::new(Estimator {
                input: typed(cx.inputs.first())?,
                output: publisher(cx.outputs.first(), cx.outbox)?,
                filter: VelocityFilter::new(cx.param_f64("cutoff_hz", 10.0)?),
                last_seq: None,
                origin: None,
            }) as Box<dyn Work>)
        }),
    }
}

/// An estimator's state.
pub struct Estimator {
    /// Input.
    pub input: Arc<Subscription<PositionMsg>>,
    /// Output.
    pub output: Publisher<StateMsg>,
    /// The filter.
    pub filter: VelocityFilter,
    /// `seq` of the last measurement fed to the filter.
    pub last_seq: Option<u64>,
    /// Origin of the newest measurement used.
    pub origin: Option<Nanos>,
}

impl Work for Estimator {
    fn save(&self) -> Option<ratelab_core::node::NodeState> {
        Some(Box::new((self.filter.clone(), self.last_seq, self.origin)))
    }
    fn load(&mut self, state: &ratelab_core::node::NodeState) -> bool {
        type Kept = (VelocityFilter, Option<u64>, Option<Nanos>);
        let Some((filter, last_seq, origin)) = state.downcast_ref::<Kept>() else {
            return false;
        };
        self.filter.clone_from(filter);
        (self.last_seq, self.origin) = (*last_seq, *origin);
        true
    }
    fn tick(&mut self, now: Nanos) -> Flow {
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
