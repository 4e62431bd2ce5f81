//! The Python layer's side of the runtime's **python** kind and `--policy FILE.py` brains:
//! the interpreter the runtime calls to make them ([`Embedded`], installed by [`crate::install`]).

use crate::brain::PythonBrain;
use crate::node::PythonNode;
use ratelab_core::ports::{AnyPorts, RustNode};
use ratelab_core::rate::Rate;
use ratelab_core::time::Nanos;
use ratelab_runtime::graph::interpreter::{BrainLoadError, Interpreter};
use ratelab_runtime::graph::kind::{BuildContext, NodeOf, PythonCode};
use ratelab_runtime::policy::Policy;

/// The embedded interpreter (PyO3) as the runtime calls it.
pub struct Embedded;

impl Interpreter for Embedded {
    fn node(&self, cx: &mut BuildContext<'_>, code: &PythonCode) -> Result<NodeOf, String> {
        let node = PythonNode::load(cx, code).map_err(|e| e.to_string())?;
        let rate = cx.adapter.rate.clone();
        NodeOf::bind(cx, Python { node, rate })
    }

    fn brain(&self, script: &str, function: &str) -> Result<Box<dyn Policy>, BrainLoadError> {
        let brain = PythonBrain::load(script, function).map_err(|e| BrainLoadError {
            missing: matches!(e, crate::PythonError::Input { missing: true, .. }),
            line: e.to_string(),
        })?;
        Ok(Box::new(brain))
    }

    fn enter_trial(&self) -> u64 {
        crate::enter_trial()
    }

    fn interrupt_trial(&self, thread: u64) -> bool {
        crate::interrupt_trial(thread)
    }
}

/// A Python node with its rate (a timer's period is a whole number of ticks): an adapter
/// whose topics are any ([`AnyPorts`]), read and published by the Python node itself.
struct Python {
    node: PythonNode,
    rate: Rate,
}

impl RustNode for Python {
    type Input = AnyPorts;
    type Output = AnyPorts;

    fn tick(&mut self, now: Nanos, (): ()) {
        if let Err(e) = self.node.tick(now, self.rate.period()) {
            // The scheduler catches it and fails the node with this line.
            panic!("{}", e.0);
        }
    }
}
