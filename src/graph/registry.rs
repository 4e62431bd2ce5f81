//! Node kinds written in Rust outside ratelab: a registry from the name a graph file gives
//! as `kind` to the code that makes such a node.
//!
//! A kind is a type implementing [`RustNode`] with a typed input and output (copper-rs's
//! `CuTask` is the model): any [`Message`] — [`StateMsg`], [`PositionMsg`] or [`ForceMsg`]
//! today. [`register`] it once, before the graph file is read; from then on
//! `kind = "NAME"` in a graph file makes one, with the file's `params = { … }`:
//!
//! ```no_run
//! use ratelab::graph::registry::{register, NodeContext, RustNode};
//! use ratelab::msg::{ForceMsg, StateMsg};
//! use ratelab::Nanos;
//!
//! struct Hold(f64);
//! impl RustNode for Hold {
//!     type Input = StateMsg;
//!     type Output = ForceMsg;
//!     fn tick(&mut self, _now: Nanos, _input: Option<&StateMsg>) -> Option<ForceMsg> {
//!         Some(ForceMsg { newtons: self.0 })
//!     }
//! }
//! register("hold", |cx: &NodeContext| Ok(Hold(cx.param_f64("newtons", 0.0)?))).unwrap();
//! ```
//!
//! **At run time**, a tick of a registered node reads its input topic by the topic's QoS
//! (latest: the newest unread; fifo: the oldest unread) and passes it to
//! [`RustNode::tick`] when it is new (`None` when nothing arrived since the last tick: a
//! node that needs the last value keeps it, as the chapter's nodes do); what `tick` returns
//! is published at the tick's end (its time, plus its `compute_ms` if the graph file gives
//! one: [`crate::executor`]), carrying the origin stamp of the newest input the node
//! was given (its own tick time before the first), so the actuator measures sense→act
//! latency across it as across any node. A registered kind takes the place of a policy
//! (`state` in, `force` out), a safety node (`force` → `force`) or an estimator
//! (`position` → `state`) in the chapter's chain, like a Python node.
//!
//! **Limits.** One input and one output per node (as every kind has today); the registry
//! is per process, so a graph with a registered kind runs in the process that registered
//! it (`ratelab launch --processes` starts `ratelab` binaries, which know only the built-in
//! kinds, and refuses it by name).

use crate::msg::{AnyTopic, ForceMsg, MsgType, PositionMsg, StateMsg};
use crate::publisher::{Outbox, Publisher};
use crate::time::Nanos;
use crate::topic::Topic;
use std::collections::BTreeMap;
use std::sync::{Arc, RwLock};

/// The most kinds one process may register.
pub const MAX_KINDS: usize = 64;

/// A message a registered node may read or publish: one of the graph's message types.
pub trait Message: Clone + Send + Sync + 'static {
    /// The type a graph file names (`state`, `position`, `force`).
    const TYPE: MsgType;
    /// `t` as a topic of this type, if it is one.
    fn topic(t: &AnyTopic) -> Option<&Arc<Topic<Self>>>;
}

impl Message for StateMsg {
    const TYPE: MsgType = MsgType::State;
    fn topic(t: &AnyTopic) -> Option<&Arc<Topic<Self>>> {
        match t {
            AnyTopic::State(t) => Some(t),
            _ => None,
        }
    }
}

impl Message for PositionMsg {
    const TYPE: MsgType = MsgType::Position;
    fn topic(t: &AnyTopic) -> Option<&Arc<Topic<Self>>> {
        match t {
            AnyTopic::Position(t) => Some(t),
            _ => None,
        }
    }
}

impl Message for ForceMsg {
    const TYPE: MsgType = MsgType::Force;
    fn topic(t: &AnyTopic) -> Option<&Arc<Topic<Self>>> {
        match t {
            AnyTopic::Force(t) => Some(t),
            _ => None,
        }
    }
}

/// A node of a registered kind: one typed input, one typed output.
pub trait RustNode: Send + 'static {
    /// What it reads.
    type Input: Message;
    /// What it publishes.
    type Output: Message;
    /// One tick at run time `now`. `input` is the message the topic delivered since the
    /// last tick (`None`: nothing new). The message returned, if any, is published now.
    fn tick(&mut self, now: Nanos, input: Option<&Self::Input>) -> Option<Self::Output>;
}

/// What making a node is given: its name and settings from the graph file and the run.
#[derive(Debug)]
pub struct NodeContext<'a> {
    /// The node's name in the graph file.
    pub name: &'a str,
    /// Its period at the start of the run (1 / `rate_hz`).
    pub period: Nanos,
    /// The run's seed (for a node that draws random numbers: derive its generator from it,
    /// and a virtual run stays byte-identical).
    pub seed: u64,
    /// The graph file's `params = { … }` for it.
    pub params: &'a toml::Table,
}

impl NodeContext<'_> {
    /// Parameter `key` as a number (an integer in the file is taken as one), or `default`
    /// when the file does not set it.
    ///
    /// # Errors
    /// A one-line reason naming the node and the key when it is not a finite number.
    pub fn param_f64(&self, key: &str, default: f64) -> Result<f64, String> {
        match self.params.get(key) {
            None => Ok(default),
            Some(toml::Value::Float(x)) if x.is_finite() => Ok(*x),
            Some(toml::Value::Integer(i)) => Ok(*i as f64),
            Some(v) => Err(format!(
                "node '{}': params.{key} must be a number, got {v}",
                self.name
            )),
        }
    }
}

/// Why a kind cannot be registered.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegistryError {
    /// The name is not 1 to 32 lowercase letters, digits or '_', starting with a letter.
    #[error(
        "node kind '{0}' must be 1 to 32 lowercase letters, digits or '_', starting with a letter"
    )]
    BadName(String),
    /// The name is a built-in kind's or was registered before.
    #[error("node kind '{0}' is already taken")]
    Taken(String),
    /// [`MAX_KINDS`] kinds are registered already.
    #[error("at most {MAX_KINDS} node kinds can be registered")]
    Full,
}

/// A registered node bound to its topics, ready to tick: what the registry makes of a
/// [`RustNode`] (write a `RustNode`, not this).
pub trait Tick: Send {
    /// One tick at run time `now`: read, [`RustNode::tick`], publish.
    fn tick(&mut self, now: Nanos);
}

type Make = dyn Fn(&NodeContext<'_>, &AnyTopic, &AnyTopic, &Outbox) -> Result<Box<dyn Tick>, String>
    + Send
    + Sync;

struct Entry {
    input: MsgType,
    output: MsgType,
    make: Box<Make>,
}

fn registry() -> &'static RwLock<BTreeMap<String, Entry>> {
    static REGISTRY: RwLock<BTreeMap<String, Entry>> = RwLock::new(BTreeMap::new());
    &REGISTRY
}

/// The built-in kinds' names, as a graph file spells them (`NodeKind` in
/// [`crate::graph::spec`]): a registered kind may not take one.
pub const BUILT_IN_KINDS: [&str; 7] = [
    "sensor",
    "estimator",
    "policy",
    "safety",
    "actuator",
    "python",
    "external",
];

/// Register node kind `kind`: a graph file's `kind = "<kind>"` then makes a node with
/// `make`, given the node's [`NodeContext`].
///
/// # Errors
/// [`RegistryError`]: a bad or taken name, or too many kinds.
pub fn register<N, F>(kind: &str, make: F) -> Result<(), RegistryError>
where
    N: RustNode,
    F: Fn(&NodeContext<'_>) -> Result<N, String> + Send + Sync + 'static,
{
    let valid = !kind.is_empty()
        && kind.len() <= 32
        && kind.starts_with(|c: char| c.is_ascii_lowercase())
        && kind
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
    if !valid {
        return Err(RegistryError::BadName(kind.to_string()));
    }
    let mut reg = registry().write().unwrap_or_else(|e| e.into_inner());
    if BUILT_IN_KINDS.contains(&kind) || reg.contains_key(kind) {
        return Err(RegistryError::Taken(kind.to_string()));
    }
    if reg.len() >= MAX_KINDS {
        return Err(RegistryError::Full);
    }
    let make = move |cx: &NodeContext<'_>, input: &AnyTopic, output: &AnyTopic, outbox: &Outbox| {
        let (Some(input), Some(output)) = (N::Input::topic(input), N::Output::topic(output)) else {
            // The graph file's types were checked against the kind's when it was read.
            return Err(format!("node '{}': its topics' types changed", cx.name));
        };
        let node = make(cx)?;
        Ok(Box::new(Bound {
            node,
            input: input.clone(),
            output: Publisher::new(output.clone(), outbox.clone()),
            last_seq: None,
            origin: None,
        }) as Box<dyn Tick>)
    };
    reg.insert(
        kind.to_string(),
        Entry {
            input: N::Input::TYPE,
            output: N::Output::TYPE,
            make: Box::new(make),
        },
    );
    Ok(())
}

/// What registered kind `kind` reads and publishes, if it is registered.
pub fn shape(kind: &str) -> Option<(MsgType, MsgType)> {
    let reg = registry().read().unwrap_or_else(|e| e.into_inner());
    reg.get(kind).map(|e| (e.input, e.output))
}

/// Every registered kind's name, sorted.
pub fn kinds() -> Vec<String> {
    let reg = registry().read().unwrap_or_else(|e| e.into_inner());
    reg.keys().cloned().collect()
}

/// Make a node of registered kind `kind`, bound to `input` and `output` (published through
/// the node's `outbox`).
///
/// # Errors
/// A one-line reason: the kind is not registered in this process, or its maker refused
/// the node's parameters.
pub(crate) fn make(
    kind: &str,
    cx: &NodeContext<'_>,
    input: &AnyTopic,
    output: &AnyTopic,
    outbox: &Outbox,
) -> Result<Box<dyn Tick>, String> {
    let reg = registry().read().unwrap_or_else(|e| e.into_inner());
    let entry = reg.get(kind).ok_or_else(|| {
        format!(
            "node '{}': kind '{kind}' is not registered in this process (a Rust node kind \
             runs in the program that registers it)",
            cx.name
        )
    })?;
    (entry.make)(cx, input, output, outbox)
}

/// A node with its topics and what it has been given.
struct Bound<N: RustNode> {
    node: N,
    input: Arc<Topic<N::Input>>,
    output: Publisher<N::Output>,
    /// `seq` of the newest message given to the node.
    last_seq: Option<u64>,
    /// Origin stamp of the newest message given to the node.
    origin: Option<Nanos>,
}

impl<N: RustNode> Tick for Bound<N> {
    fn tick(&mut self, now: Nanos) {
        let input = self.input.read(now).and_then(|m| {
            (self.last_seq != Some(m.seq)).then(|| {
                self.last_seq = Some(m.seq);
                self.origin = Some(m.origin_stamp.unwrap_or(m.stamp));
                m.data
            })
        });
        if let Some(out) = self.node.tick(now, input.as_ref()) {
            self.output.publish(out, now, self.origin.or(Some(now)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Echo;
    impl RustNode for Echo {
        type Input = ForceMsg;
        type Output = ForceMsg;
        fn tick(&mut self, _now: Nanos, input: Option<&ForceMsg>) -> Option<ForceMsg> {
            input.copied()
        }
    }

    #[test]
    fn names_are_checked_and_taken_once() {
        let ok = |_: &NodeContext<'_>| Ok(Echo);
        assert_eq!(
            register("Bad-Name", ok),
            Err(RegistryError::BadName("Bad-Name".into()))
        );
        assert_eq!(
            register("policy", ok),
            Err(RegistryError::Taken("policy".into()))
        );
        assert_eq!(register("echo_unit", ok), Ok(()));
        assert_eq!(
            register("echo_unit", ok),
            Err(RegistryError::Taken("echo_unit".into()))
        );
        assert_eq!(shape("echo_unit"), Some((MsgType::Force, MsgType::Force)));
        assert!(kinds().contains(&"echo_unit".to_string()));
        assert_eq!(shape("nobody"), None);
    }

    #[test]
    fn a_bound_node_gets_each_message_once_and_passes_its_origin_on() {
        register("echo_bound", |_: &NodeContext<'_>| Ok(Echo)).unwrap();
        let input = AnyTopic::new("/in", MsgType::Force, 1).unwrap();
        let output = AnyTopic::new("/out", MsgType::Force, 1).unwrap();
        let params = toml::Table::new();
        let cx = NodeContext {
            name: "e",
            period: Nanos(20),
            seed: 0,
            params: &params,
        };
        let mut node = make("echo_bound", &cx, &input, &output, &Outbox::new()).unwrap();
        let (AnyTopic::Force(i), AnyTopic::Force(o)) = (&input, &output) else {
            unreachable!()
        };
        i.publish(ForceMsg { newtons: 3.0 }, Nanos(5), Some(Nanos(1)));
        node.tick(Nanos(10));
        let m = o.read(Nanos(10)).unwrap();
        assert_eq!(
            (m.data.newtons, m.stamp, m.origin_stamp),
            (3.0, Nanos(10), Some(Nanos(1)))
        );
        // Nothing new: Echo publishes nothing.
        node.tick(Nanos(30));
        assert_eq!(o.stats().published, 1);
        assert!(make("nobody", &cx, &input, &output, &Outbox::new())
            .err()
            .unwrap()
            .contains("kind 'nobody' is not registered"));
    }
}
