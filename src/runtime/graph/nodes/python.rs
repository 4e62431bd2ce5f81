//! The **python** kind: a learner's node written in Python, shaped like an rclpy node
//! (`script = "nodes/NAME.py"`, optional `class` and `params`). Any inputs and outputs, of
//! any message type. Its runtime is the Python layer's (`ratelab::python::node`), reached
//! through the interpreter it installs ([`crate::graph::interpreter`]).

use crate::graph::kind::{BuildContext, Code, KindDef, Params, Plant, Ports};
use ratelab_core::limits::MAX_NODE_PORTS;

/// The kind.
pub fn def() -> KindDef {
    KindDef {
        name: "python",
        doc: "a learner's node in Python (create_subscription, create_publisher, create_timer)",
        ports: Ports::Open {
            max_inputs: MAX_NODE_PORTS,
            min_outputs: 0,
            max_outputs: MAX_NODE_PORTS,
        },
        plant: Plant::None,
        code: Code::Python,
        params: Params::Free,
        uses_brain: false,
        // The Python layer's adapter, a `RustNode` of any topics, bound by it.
        make: Box::new(|cx: &mut BuildContext<'_>| {
            let code = cx
                .adapter
                .python
                .ok_or_else(|| format!("python node '{}' names no script", cx.node.name))?;
            crate::graph::interpreter::installed()?.node(cx, code)
        }),
    }
}
