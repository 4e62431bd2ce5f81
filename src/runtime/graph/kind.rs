//! What a node kind is: the one definition a graph file's `kind = "…"` names
//! ([`KindDef`]), and what making a node of it is given ([`BuildContext`]).
//!
//! Every kind — the built-in ones (one file each in [`super::nodes`]; `ratelab kinds`
//! lists them) and the kinds a Rust program registers ([`super::registry`]) — is one
//! [`KindDef`] in one registry ([`super::registry::kind`]), and every kind's node is a
//! [`RustNode`] (typed inputs and outputs, one `tick`: [`ratelab_core::ports`]) bound to its
//! topics ([`NodeOf::bind`]); a Python node and a ROS 2 node's proxy are adapters of it
//! whose ports are any topics ([`ratelab_core::ports::AnyPorts`]). The graph file's rules
//! ([`super::spec`]) read only the definition: what the kind reads and publishes
//! ([`Ports`]), how it touches the plant ([`Plant`]), whose code it runs ([`Code`]) and
//! which parameters it takes ([`Params`]); [`super::Graph::build`] calls its `make` with a
//! [`BuildContext`] grouped by which kinds use what: [`NodeContext`] (every kind; all a
//! program's kind made through `register` is given), [`RunParts`] (the chain's kinds:
//! plant, brain, log) and [`AdapterParts`] (the Python and ROS 2 adapters).
//!
//! A leaf of the graph module: it knows message types, topics and the plant, not the graph
//! file or the graph built from it.

use crate::plant::SharedPlant;
use crate::policy::BrainSlot;
use ratelab_core::ids::NodeId;
use ratelab_core::limits::MAX_NODE_PORTS;
use ratelab_core::msg::{AnyTopic, MsgType};
use ratelab_core::node::{Flow, NodeState};
use ratelab_core::ports::{Inputs, Outputs, RustNode};
use ratelab_core::publisher::Outbox;
use ratelab_core::qos::Liveliness;
use ratelab_core::rate::Rate;
use ratelab_core::runlog::{RunLog, StepSink};
use ratelab_core::time::Nanos;
use std::any::Any;
use std::fmt;
use std::sync::{Arc, Mutex};

/// What a node of a kind reads and publishes.
#[derive(Clone, Debug, PartialEq)]
pub enum Ports {
    /// Exactly these topics, one each, in the graph file's order: per input and per output,
    /// the message types it may carry (a sensor publishes `state` or `position`).
    Fixed {
        /// Per input, the types it accepts.
        inputs: Vec<&'static [MsgType]>,
        /// Per output, the types it may publish.
        outputs: Vec<&'static [MsgType]>,
    },
    /// Any topics of any type, within bounds (a Python node; an external node, one output).
    Open {
        /// The most inputs.
        max_inputs: usize,
        /// The fewest outputs.
        min_outputs: usize,
        /// The most outputs.
        max_outputs: usize,
    },
}

/// How a kind touches the plant (the one cartpole the graph runs around).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Plant {
    /// Not at all: it sees only topics.
    None,
    /// It reads the plant (a sensor): it may head the chapter's chain, and across processes
    /// it runs in the plant's process.
    Reads,
    /// It steps the plant (the actuator): exactly one per graph, at the plant's rate, its
    /// ticks taking no compute time.
    Steps,
}

/// Whose code a kind runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Code {
    /// ratelab's own.
    BuiltIn,
    /// A learner's Python script (`script = "…"`, optional `class`).
    Python,
    /// A kind a Rust program registered ([`super::registry::register`]).
    Rust,
    /// A ROS 2 node's, over `--ros2` (`ratelab::ros2::external`): ratelab runs a proxy.
    Ros2,
}

/// One numeric parameter of a kind (`params = { NAME = … }`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamDef {
    /// Its name.
    pub name: &'static str,
    /// Its unit, as shown (`m`, `Hz`, `N`).
    pub unit: &'static str,
    /// What it is.
    pub doc: &'static str,
    /// Its value when the file does not give one.
    pub default: f64,
    /// The smallest value accepted.
    pub min: f64,
    /// The largest value accepted.
    pub max: f64,
}

/// The parameters a kind takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Params {
    /// These numbers, each checked against its range when the file is read; the ones the
    /// file leaves out take their defaults.
    Numbers(&'static [ParamDef]),
    /// Any table of numbers, strings, booleans and arrays of them, read by the node's own
    /// code (a Python node's `get_parameter`, a registered kind's maker).
    Free,
}

/// A Python node's code: its script and class (the graph file's `script` and `class`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PythonCode {
    /// The script, as an absolute path (the file's `script` is relative to the graph file's
    /// folder).
    pub script: String,
    /// The class to instantiate; `None`: the script's one class that takes a node handle.
    pub class: Option<String>,
}

/// A node at run time, its kind's [`RustNode`] bound to its topics ([`NodeOf::bind`]): what
/// the graph's node runs on a tick. ratelab's side of [`RustNode`], never written by a kind.
pub(crate) trait Work: Send {
    /// One tick at run time `now` (a node whose code failed panics, see [`RustNode::tick`]).
    fn tick(&mut self, now: Nanos) -> Flow;
    /// [`RustNode::alive_by_ticking`].
    fn alive_by_ticking(&self) -> bool;
    /// The node's state and its inputs' positions ([`RustNode::save`]).
    fn save(&self) -> Option<NodeState>;
    /// Take back what [`Work::save`] gave.
    fn load(&mut self, state: &NodeState) -> bool;
}

/// A node of a kind, bound to its topics: what a kind's `make` returns ([`NodeOf::bind`]).
pub struct NodeOf(pub(crate) Box<dyn Work>);

impl NodeOf {
    /// `node` bound to the topics `cx` gives: each input read by its slot at every tick
    /// ([`Inputs`]), what each tick returns published through `cx.outbox` with the oldest
    /// origin its inputs delivered (its tick time for a source).
    ///
    /// # Errors
    /// One line naming the node when its topics are not of `N`'s types (the graph file's
    /// rules check them against the kind's [`Ports`] when it is read).
    pub fn bind<N: RustNode>(cx: &BuildContext<'_>, node: N) -> Result<NodeOf, String> {
        Ok(NodeOf::of(node, ports::<N>(cx)?))
    }

    /// `node`, which reads and publishes nothing, bound to no topics
    /// ([`super::nodes::GraphNode::idle`], the schedulers' tests).
    pub(crate) fn unbound<N: RustNode<Input = (), Output = ()>>(node: N) -> NodeOf {
        NodeOf::of(node, ((), ()))
    }

    /// `node` on its bound ports.
    fn of<N: RustNode>(node: N, (inputs, outputs): BoundPorts<N>) -> NodeOf {
        NodeOf(Box::new(Bound::<N> {
            node,
            inputs,
            outputs,
        }))
    }
}

/// A node's inputs and outputs, bound to their topics.
type BoundPorts<N> = (
    <<N as RustNode>::Input as Inputs>::Ports,
    <<N as RustNode>::Output as Outputs>::Ports,
);

/// `N`'s inputs and outputs bound to the topics `cx` gives.
///
/// # Errors
/// One line naming the node when its topics are not of `N`'s types.
fn ports<N: RustNode>(cx: &BuildContext<'_>) -> Result<BoundPorts<N>, String> {
    match (
        <N::Input as Inputs>::bind(cx.node.inputs),
        <N::Output as Outputs>::bind(cx.node.outputs, cx.outbox),
    ) {
        (Some(inputs), Some(outputs)) => Ok((inputs, outputs)),
        _ => Err(format!(
            "node '{}': its topics are not of the types its kind reads and publishes",
            cx.node.name
        )),
    }
}

impl fmt::Debug for NodeOf {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("NodeOf(..)")
    }
}

/// A node with its topics.
struct Bound<N: RustNode> {
    node: N,
    inputs: <N::Input as Inputs>::Ports,
    outputs: <N::Output as Outputs>::Ports,
}

/// A bound node's state ([`Work::save`]): its own, and where its inputs stand.
struct BoundState<M> {
    node: NodeState,
    marks: M,
}

impl<N: RustNode> Work for Bound<N> {
    fn tick(&mut self, now: Nanos) -> Flow {
        let delivered = <N::Input as Inputs>::read(&mut self.inputs, now);
        let out = self.node.tick(now, delivered);
        // The oldest origin its inputs delivered; a source's data begins at its tick.
        let origin = if <N::Input as Inputs>::TYPES.is_empty() {
            Some(now)
        } else {
            <N::Input as Inputs>::oldest_origin(&self.inputs).or(Some(now))
        };
        <N::Output as Outputs>::publish(&self.outputs, out, now, origin);
        <N::Input as Inputs>::release(&mut self.inputs);
        self.node.flow()
    }
    fn alive_by_ticking(&self) -> bool {
        self.node.alive_by_ticking()
    }
    fn save(&self) -> Option<NodeState> {
        Some(Box::new(BoundState {
            node: self.node.save()?,
            marks: <N::Input as Inputs>::marks(&self.inputs),
        }))
    }
    fn load(&mut self, state: &NodeState) -> bool {
        type Kept<N> = BoundState<<<N as RustNode>::Input as Inputs>::Marks>;
        let Some(s) = state.downcast_ref::<Kept<N>>() else {
            return false;
        };
        if !self.node.load(&s.node) {
            return false;
        }
        <N::Input as Inputs>::set_marks(&mut self.inputs, &s.marks);
        true
    }
}

/// What every node is made from: its settings from the graph file and its topics. All a
/// program's own kind is given ([`super::registry::register`]).
#[derive(Debug)]
pub struct NodeContext<'a> {
    /// The node's name in the graph file.
    pub name: &'a str,
    /// Its index in the graph (its tie-break rank).
    pub id: NodeId,
    /// Its period at the start of the run (1 / `rate_hz`).
    pub period: Nanos,
    /// The run's seed (for a node that draws random numbers: derive its generator from it,
    /// and a virtual run stays byte-identical).
    pub seed: u64,
    /// The graph file's `params = { … }` for it: for [`Params::Numbers`], every declared
    /// one, checked.
    pub params: &'a toml::Table,
    /// The topics it reads, in the file's order, of the types its [`Ports`] allow (a kind
    /// may keep one to ask its QoS: the actuator's deadline reaction).
    pub inputs: &'a [AnyTopic],
    /// The topics it publishes, likewise.
    pub outputs: &'a [AnyTopic],
}

impl NodeContext<'_> {
    /// Parameter `key` as a number (an integer in the file is taken as one): its checked
    /// value for a kind of [`Params::Numbers`], `default` when the file does not give it.
    ///
    /// # Errors
    /// A one-line reason naming the node and the key when it is not a finite number.
    pub fn param_f64(&self, key: &str, default: f64) -> Result<f64, String> {
        param_f64(self.name, self.params, key, default)
    }
}

/// The run's shared parts, for the kinds that touch the plant ([`Plant`]), run the brain
/// or write the run's log: the chapter's chain.
pub struct RunParts<'a> {
    /// The plant.
    pub plant: &'a SharedPlant,
    /// The run's brain (`--policy`).
    pub brain: &'a BrainSlot,
    /// The run's log (the actuator writes it).
    pub log: &'a Arc<Mutex<RunLog>>,
    /// Every topic of the graph, by id (the actuator's per-step counters).
    pub topics: &'a [AnyTopic],
    /// The topic the chapter's policy publishes, when the graph has the chain (the
    /// actuator reports what was published on it).
    pub action: Option<&'a AnyTopic>,
    /// The policy's queue of the chain's state estimate, when the graph has an estimator
    /// ([`crate::graph::GraphSpec::estimate_topic`]; the actuator watches it).
    pub estimate: Option<AnyTopic>,
    /// Told of every actuator step (the actuator takes them).
    pub observers: &'a mut Option<Vec<Box<dyn StepSink>>>,
}

/// What an adapter of code that lives elsewhere is given beside its topics (a Python node,
/// a ROS 2 node's proxy: kinds of [`AnyPorts`](ratelab_core::ports::AnyPorts), which read
/// and publish themselves).
pub struct AdapterParts<'a> {
    /// A Python node's script and class.
    pub python: Option<&'a PythonCode>,
    /// Its rate (shared: it can change while the graph runs).
    pub rate: &'a Rate,
    /// Its liveliness (a ROS 2 node's proxy asserts it when a message arrives).
    pub liveliness: &'a Arc<Liveliness>,
    /// What the graph made for this node before it (an external node's port).
    pub attachment: Option<Arc<dyn Any + Send + Sync>>,
}

/// Everything making one node is given, by what each kind needs: [`NodeContext`] (every
/// kind), [`RunParts`] (the chain's kinds), [`AdapterParts`] (Python and ROS 2 adapters),
/// and the outbox its publishers publish through.
pub struct BuildContext<'a> {
    /// The node's settings and topics.
    pub node: NodeContext<'a>,
    /// The run's plant, brain, log and watchers.
    pub run: RunParts<'a>,
    /// What an adapter is given.
    pub adapter: AdapterParts<'a>,
    /// Its outbox: publish through it (held during a tick with a compute time).
    pub outbox: &'a Outbox,
}

/// `params[key]` as a number (an integer is taken as one), `default` when absent.
///
/// # Errors
/// A one-line reason naming node `name` and the key when it is not a finite number.
pub fn param_f64(name: &str, params: &toml::Table, key: &str, default: f64) -> Result<f64, String> {
    match params.get(key) {
        None => Ok(default),
        Some(toml::Value::Float(x)) if x.is_finite() => Ok(*x),
        Some(toml::Value::Integer(i)) => Ok(*i as f64),
        Some(v) => Err(format!(
            "node '{name}': params.{key} must be a number, got {v}"
        )),
    }
}

/// Make a running node of a kind.
pub type Make = dyn Fn(&mut BuildContext<'_>) -> Result<NodeOf, String> + Send + Sync;

/// A node kind: the one definition the graph file's rules and the graph's builder read.
pub struct KindDef {
    /// The name a graph file gives as `kind`.
    pub name: &'static str,
    /// One line on what it does.
    pub doc: &'static str,
    /// What it reads and publishes.
    pub ports: Ports,
    /// How it touches the plant.
    pub plant: Plant,
    /// Whose code it runs.
    pub code: Code,
    /// Its parameters.
    pub params: Params,
    /// Does it run the run's brain (`--policy`)? The built-in `policy` does.
    pub uses_brain: bool,
    /// Make a node of it.
    pub make: Box<Make>,
}

impl KindDef {
    /// Kind `name`, whose nodes are the [`RustNode`]s `make` makes, bound to their topics
    /// ([`NodeOf::bind`]). Its ports are `N`'s: its input and output types, one topic each
    /// ([`Ports::Fixed`]), or any topics up to [`MAX_NODE_PORTS`] each way for
    /// [`ratelab_core::ports::AnyPorts`]. The rest are a program's kind's: no docs, no
    /// plant, [`Code::Rust`], any table of parameters, no brain. A built-in kind sets its
    /// own over these (`KindDef { plant: Plant::Reads, ..KindDef::of(…) }`).
    pub fn of<N, F>(name: &str, make: F) -> KindDef
    where
        N: RustNode,
        F: Fn(&mut BuildContext<'_>) -> Result<N, String> + Send + Sync + 'static,
    {
        KindDef {
            name: Box::leak(name.to_string().into_boxed_str()),
            doc: "",
            ports: ports_of::<N>(),
            plant: Plant::None,
            code: Code::Rust,
            params: Params::Free,
            uses_brain: false,
            // Its topics bound first: a node is made only for topics it can use.
            make: Box::new(move |cx: &mut BuildContext<'_>| {
                let ports = ports::<N>(cx)?;
                Ok(NodeOf::of(make(cx)?, ports))
            }),
        }
    }
}

/// The ports of a kind whose nodes are `N`s: one topic per input and output type, or
/// [`Ports::Open`] for [`ratelab_core::ports::AnyPorts`].
pub fn ports_of<N: RustNode>() -> Ports {
    if <N::Input as Inputs>::OPEN || <N::Output as Outputs>::OPEN {
        return Ports::Open {
            max_inputs: MAX_NODE_PORTS,
            min_outputs: 0,
            max_outputs: MAX_NODE_PORTS,
        };
    }
    let one = |types: &'static [MsgType]| -> Vec<&'static [MsgType]> {
        types.iter().map(std::slice::from_ref).collect()
    };
    Ports::Fixed {
        inputs: one(<N::Input as Inputs>::TYPES),
        outputs: one(<N::Output as Outputs>::TYPES),
    }
}

impl fmt::Debug for KindDef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("KindDef")
            .field("name", &self.name)
            .field("ports", &self.ports)
            .field("plant", &self.plant)
            .field("code", &self.code)
            .finish_non_exhaustive()
    }
}

/// A registered kind: a cheap handle (compare, hash and print by name).
#[derive(Clone, Copy)]
pub struct Kind(pub(crate) &'static KindDef);

impl Kind {
    /// Its definition.
    pub fn def(self) -> &'static KindDef {
        self.0
    }
    /// Its name, as a graph file spells it.
    pub fn as_str(self) -> &'static str {
        self.0.name
    }
    /// How it touches the plant.
    pub fn plant(self) -> Plant {
        self.0.plant
    }
    /// Whose code it runs.
    pub fn code(self) -> Code {
        self.0.code
    }
    /// Is it the actuator (it steps the plant)?
    pub fn is_actuator(self) -> bool {
        self.0.plant == Plant::Steps
    }
}

impl PartialEq for Kind {
    fn eq(&self, other: &Kind) -> bool {
        self.0.name == other.0.name
    }
}
impl Eq for Kind {}

impl std::hash::Hash for Kind {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        self.0.name.hash(h);
    }
}

impl fmt::Debug for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Kind({})", self.0.name)
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.0.name)
    }
}

/// The topic `t` as a typed topic of `M`, for a kind whose ports fix its type.
///
/// # Errors
/// One line naming the topic, when it carries another type (the graph file's rules make
/// that impossible for a validated graph).
pub fn typed<M: ratelab_core::msg::Message>(
    t: Option<&AnyTopic>,
) -> Result<Arc<ratelab_core::topic::Subscription<M>>, String> {
    match t {
        Some(t) => t
            .typed::<M>()
            .cloned()
            .ok_or_else(|| format!("topic {} does not carry {}", t.name(), M::NAME)),
        None => Err(format!("no topic of {}", M::NAME)),
    }
}

/// A publisher of `M` on topic `t` through `outbox` (into every subscription's queue), for
/// a kind whose ports fix its type.
///
/// # Errors
/// One line naming the topic, when it carries another type (the graph file's rules make
/// that impossible for a validated graph).
pub fn publisher<M: ratelab_core::msg::Message>(
    t: Option<&AnyTopic>,
    outbox: &Outbox,
) -> Result<ratelab_core::publisher::Publisher<M>, String> {
    match t {
        Some(t) => t
            .publisher::<M>(outbox)
            .ok_or_else(|| format!("topic {} does not carry {}", t.name(), M::NAME)),
        None => Err(format!("no topic of {}", M::NAME)),
    }
}
