//! The Python layer's side of the runtime's **python** kind and `--policy FILE.py` brains:
//! the interpreter the runtime calls to make them ([`Embedded`], installed by [`crate::install`]).

use crate::brain::PythonBrain;
use crate::node::PythonNode;
use ratelab_core::node::Flow;
use ratelab_core::rate::Rate;
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::interpreter::Interpreter;
use ratelab_runtime::graph::kind::{BuildContext, PythonCode, Work};
use ratelab_runtime::policy::Policy;

/// The embedded interpreter (PyO3) as the runtime calls it.
pub struct Embedded;

impl Interpreter for Embedded {
    fn node(&self, cx: &mut BuildContext<'_>, code: &PythonCode) -> Result<Box<dyn Work>, String> {
        let node = PythonNode::load(cx, code).map_err(|e| e.to_string())?;
        Ok(Box::new(Python {
            node,
            rate: cx.rate.clone(),
        }))
    }

    fn brain(&self, script: &str, function: &str) -> Result<Box<dyn Policy>, String> {
        Ok(Box::new(
            PythonBrain::load(script, function).map_err(|e| e.to_string())?,
        ))
    }

    fn enter_trial(&self) -> u64 {
        crate::enter_trial()
    }

    fn interrupt_trial(&self, thread: u64) -> bool {
        crate::interrupt_trial(thread)
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
