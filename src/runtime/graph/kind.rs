//! What a node kind is: the one definition a graph file's `kind = "…"` names
//! ([`KindDef`]), and what making a node of it is given ([`BuildContext`]).
//!
//! Every kind — the built-in `sensor`, `estimator`, `policy`, `safety` and `actuator`
//! (one file each in [`super::nodes`]), `python` (a learner's script), `external` (a ROS 2
//! node) and the kinds a Rust program registers ([`super::registry`]) — is one [`KindDef`]
//! in one registry ([`super::registry::kind`]). The graph file's rules ([`super::spec`])
//! read only the definition: what the kind reads and publishes ([`Ports`]), how it touches
//! the plant ([`Plant`]), whose code it runs ([`Code`]) and which parameters it takes
//! ([`Params`]); [`super::Graph::build`] calls its `make`. Nothing else matches on a
//! kind (the graph file's shorthand for the built-in kinds' parameters, `max_force_n = 8` as
//! a key of the node's table, lists their names).
//!
//! A leaf of the graph module: it knows message types, topics and the plant, not the graph
//! file or the graph built from it.

use crate::plant::SharedPlant;
use crate::policy::BrainSlot;
use ratelab_core::ids::NodeId;
use ratelab_core::msg::{AnyTopic, MsgType};
use ratelab_core::node::Flow;
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

/// A node at run time, of some kind: what it does on a tick.
pub trait Work: Send {
    /// One tick at run time `now`.
    ///
    /// # Panics
    /// A node whose code failed (a Python callback raised) panics with its one-line
    /// reason; the scheduler catches it and ends the run as "node X failed".
    fn tick(&mut self, now: Nanos) -> Flow;
    /// Does a tick assert the node's liveliness? An external node's proxy ticks whether or
    /// not the ROS 2 node is there: it asserts it when a message arrives instead.
    fn alive_by_ticking(&self) -> bool {
        true
    }
    /// The node's own state now ([`ratelab_core::node::Node::save`]): `None` (the default) when it
    /// cannot be captured, which makes a capture of its graph a replay
    /// ([`crate::runcore`]). A kind whose `tick` keeps nothing between ticks returns
    /// `Some(Box::new(()))`.
    fn save(&self) -> Option<ratelab_core::node::NodeState> {
        None
    }
    /// Take back what [`Work::save`] gave; false (nothing changed) when it is not this
    /// kind's.
    fn load(&mut self, _state: &ratelab_core::node::NodeState) -> bool {
        false
    }
}

/// Everything making one node is given: the node's settings from the graph file, its
/// topics, and the graph's shared parts.
pub struct BuildContext<'a> {
    /// The node's name.
    pub name: &'a str,
    /// Its index in the graph (its tie-break rank).
    pub id: NodeId,
    /// Its rate (shared: it can change while the graph runs).
    pub rate: &'a Rate,
    /// The run's seed (derive any generator from it: virtual runs stay byte-identical).
    pub seed: u64,
    /// Its parameters: for [`Params::Numbers`], every declared one, checked.
    pub params: &'a toml::Table,
    /// A Python node's script and class.
    pub python: Option<&'a PythonCode>,
    /// The topics it reads, in the file's order, of the types its [`Ports`] allow.
    pub inputs: &'a [AnyTopic],
    /// The topics it publishes, likewise.
    pub outputs: &'a [AnyTopic],
    /// Its outbox: publish through it (held during a tick with a compute time).
    pub outbox: &'a Outbox,
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
    /// The node's liveliness.
    pub liveliness: &'a Arc<Liveliness>,
    /// Told of every actuator step (the actuator takes them).
    pub observers: &'a mut Option<Vec<Box<dyn StepSink>>>,
    /// What the graph made for this node before it (an external node's port).
    pub attachment: Option<Arc<dyn Any + Send + Sync>>,
}

impl BuildContext<'_> {
    /// Its period at the start of the run.
    pub fn period(&self) -> Nanos {
        self.rate.period()
    }

    /// Parameter `key` as a number: its checked value for a kind of [`Params::Numbers`],
    /// `default` when the file does not give it.
    ///
    /// # Errors
    /// A one-line reason naming the node and the key when it is not a finite number.
    pub fn param_f64(&self, key: &str, default: f64) -> Result<f64, String> {
        param_f64(self.name, self.params, key, default)
    }
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
pub type Make = dyn Fn(&mut BuildContext<'_>) -> Result<Box<dyn Work>, String> + Send + Sync;

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
