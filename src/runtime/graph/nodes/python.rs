//! The **python** kind: a learner's node written in Python, shaped like an rclpy node
//! (`script = "nodes/NAME.py"`, optional `class` and `params`); its runtime is
//! [`crate::python::node`]. Any inputs and outputs, of any message type.

use crate::graph::kind::{BuildContext, Code, KindDef, Params, Plant, Ports, Work};
use crate::ids::MAX_TOPICS;
use crate::node::Flow;
use crate::python::node::PythonNode;
use crate::rate::Rate;
use crate::time::Nanos;

/// The kind.
pub fn def() -> KindDef {
    KindDef {
        name: "python",
        doc: "a learner's node in Python (create_subscription, create_publisher, create_timer)",
        ports: Ports::Open {
            max_inputs: MAX_TOPICS,
            min_outputs: 0,
            max_outputs: MAX_TOPICS,
        },
        plant: Plant::None,
        code: Code::Python,
        params: Params::Free,
        uses_brain: false,
        make: Box::new(|cx: &mut BuildContext<'_>| {
            let code = cx
                .python
                .ok_or_else(|| format!("python node '{}' names no script", cx.name))?;
            let node = PythonNode::load(cx, code).map_err(|e| e.to_string())?;
            Ok(Box::new(Python {
                node,
                rate: cx.rate.clone(),
            }) as Box<dyn Work>)
        }),
    }
}

/// A Python node with its rate (a timer's period is a whole number of ticks).
struct Python {
    node: PythonNode,
    rate: Rate,
}

impl Work for Python {
    fn tick(&mut self, now: Nanos) -> Flow {
        match self.node.tick(now, self.rate.period()) {
            Ok(()) => Flow::Continue,
            // The scheduler catches it and fails the node with this line.
            Err(e) => panic!("{}", e.0),
        }
    }
}
