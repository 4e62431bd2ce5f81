//! Node kinds written in Rust outside ratelab: a registry from the name a graph file gives
//! as `kind` to the code that makes such a node.
//!
//! A kind is a type implementing [`RustNode`] with typed inputs and outputs (copper-rs's
//! `CuTask` is the model): each a [`Message`] — [`StateMsg`], [`PositionMsg`] or
//! [`ForceMsg`] today — or a tuple of two to four of them, or `()` for none ([`Inputs`],
//! [`Outputs`]). [`register`] it once, before the graph file is read; from then on
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
//! A node of several inputs or outputs names a tuple, and the graph file lists its topics
//! in that order (`subscribes = ["/obs", "/reference"]`):
//!
//! ```no_run
//! # use ratelab::graph::registry::RustNode;
//! # use ratelab::msg::{ForceMsg, PositionMsg, StateMsg};
//! # use ratelab::Nanos;
//! struct Track { setpoint_m: f64 }
//! impl RustNode for Track {
//!     type Input = (StateMsg, PositionMsg);
//!     type Output = ForceMsg;
//!     fn tick(
//!         &mut self,
//!         _now: Nanos,
//!         (state, reference): (Option<&StateMsg>, Option<&PositionMsg>),
//!     ) -> Option<ForceMsg> {
//!         if let Some(r) = reference {
//!             self.setpoint_m = r.cart_pos_m;
//!         }
//!         let s = state?;
//!         Some(ForceMsg { newtons: -(f64::from(s[0]) - self.setpoint_m) })
//!     }
//! }
//! ```
//!
//! **At run time**, a tick of a registered node reads each input topic by the topic's QoS
//! (latest: the newest unread; fifo: the oldest unread) and passes each to
//! [`RustNode::tick`] when it is new (`None` when nothing arrived on it since the last tick:
//! a node that needs the last value keeps it, as the chapter's nodes do); what `tick`
//! returns is published at the tick's end (its time, plus its `compute_ms` if the graph
//! file gives one: [`crate::executor`]), carrying the **oldest** origin stamp among the
//! newest messages its inputs delivered (its own tick time before the first, and always for
//! a node with no inputs), so the actuator measures sense→act latency across it as across
//! any node — and a slow input (a setpoint published rarely) stretches it, since the output
//! may rest on a value that old. A registered kind takes the place of a policy (a `state`
//! input, a `force` output toward the actuator), a safety node (`force` → `force`) or an
//! estimator in the chapter's chain, like a Python node.
//!
//! **Across processes.** The registry is per process: a graph with a registered kind runs
//! in programs that register it. `ratelab launch --processes` starts `ratelab` binaries,
//! which know only the built-in kinds, and refuses such a graph by its kind's name; a
//! program of your own launches it, starting itself as each process
//! ([`crate::distributed::launcher::launch`] with `exe` its own path, and
//! [`crate::distributed::member::run_member`] for the `node` command the launcher starts it
//! with): `examples/custom_node_processes.rs` is one.

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

/// What a registered node reads: one [`Message`] type, a tuple of two to four (one topic
/// each, in the graph file's `subscribes` order), or `()` for none (a source).
///
/// A tick is given [`Inputs::Delivered`]: per input, the message its topic delivered since
/// the last tick (`None`: nothing new) — `Option<&M>` for one input, a tuple of them for
/// several, `()` for none.
pub trait Inputs: 'static {
    /// The message types, in order.
    const TYPES: &'static [MsgType];
    /// What a tick is given.
    type Delivered<'a>;
    /// The inputs bound to their topics (ratelab's side: write an `Inputs` type, not this).
    #[doc(hidden)]
    type Ports: Send;
    /// Bind to `topics` (the graph file's, types checked when it was read).
    #[doc(hidden)]
    fn bind(topics: &[AnyTopic]) -> Option<Self::Ports>;
    /// Read every input at `now` by its topic's QoS.
    #[doc(hidden)]
    fn read(ports: &mut Self::Ports, now: Nanos) -> Self::Delivered<'_>;
    /// The oldest origin among the newest messages delivered on each input; `None` before
    /// any, and for no inputs.
    #[doc(hidden)]
    fn oldest_origin(ports: &Self::Ports) -> Option<Nanos>;
}

/// What a registered node publishes: one [`Message`] type, a tuple of two to four (one
/// topic each, in the graph file's `publishes` order), or `()` for none.
///
/// A tick returns [`Outputs::Published`]: per output, the message to publish now, if any —
/// `Option<M>` for one output, a tuple of them for several, `()` for none.
pub trait Outputs: 'static {
    /// The message types, in order.
    const TYPES: &'static [MsgType];
    /// What a tick returns.
    type Published;
    /// The outputs bound to their topics (ratelab's side).
    #[doc(hidden)]
    type Ports: Send;
    /// Bind to `topics`, publishing through `outbox`.
    #[doc(hidden)]
    fn bind(topics: &[AnyTopic], outbox: &Outbox) -> Option<Self::Ports>;
    /// Publish what a tick returned, stamped `now`, carrying `origin`.
    #[doc(hidden)]
    fn publish(ports: &Self::Ports, out: Self::Published, now: Nanos, origin: Option<Nanos>);
}

/// One input bound to its topic, with what it delivered last.
#[doc(hidden)]
pub struct InPort<M: Message> {
    topic: Arc<Topic<M>>,
    /// `seq` of the newest message delivered.
    last_seq: Option<u64>,
    /// Origin stamp of the newest message delivered (its own stamp when it has none).
    origin: Option<Nanos>,
    /// The message delivered at this tick, if new.
    fresh: Option<M>,
}

impl<M: Message> InPort<M> {
    fn new(t: &AnyTopic) -> Option<InPort<M>> {
        Some(InPort {
            topic: M::topic(t)?.clone(),
            last_seq: None,
            origin: None,
            fresh: None,
        })
    }

    /// Read at `now`: the message, if new since the last read that delivered one.
    fn read(&mut self, now: Nanos) -> Option<&M> {
        self.fresh = self.topic.read(now).and_then(|m| {
            (self.last_seq != Some(m.seq)).then(|| {
                self.last_seq = Some(m.seq);
                self.origin = Some(m.origin_stamp.unwrap_or(m.stamp));
                m.data
            })
        });
        self.fresh.as_ref()
    }
}

impl Inputs for () {
    const TYPES: &'static [MsgType] = &[];
    type Delivered<'a> = ();
    type Ports = ();
    fn bind(topics: &[AnyTopic]) -> Option<()> {
        topics.is_empty().then_some(())
    }
    fn read(_: &mut (), _: Nanos) {}
    fn oldest_origin(_: &()) -> Option<Nanos> {
        None
    }
}

impl<M: Message> Inputs for M {
    const TYPES: &'static [MsgType] = &[M::TYPE];
    type Delivered<'a> = Option<&'a M>;
    type Ports = InPort<M>;
    fn bind(topics: &[AnyTopic]) -> Option<InPort<M>> {
        match topics {
            [t] => InPort::new(t),
            _ => None,
        }
    }
    fn read(ports: &mut InPort<M>, now: Nanos) -> Option<&M> {
        ports.read(now)
    }
    fn oldest_origin(ports: &InPort<M>) -> Option<Nanos> {
        ports.origin
    }
}

impl Outputs for () {
    const TYPES: &'static [MsgType] = &[];
    type Published = ();
    type Ports = ();
    fn bind(topics: &[AnyTopic], _: &Outbox) -> Option<()> {
        topics.is_empty().then_some(())
    }
    fn publish(_: &(), _: (), _: Nanos, _: Option<Nanos>) {}
}

impl<M: Message> Outputs for M {
    const TYPES: &'static [MsgType] = &[M::TYPE];
    type Published = Option<M>;
    type Ports = Publisher<M>;
    fn bind(topics: &[AnyTopic], outbox: &Outbox) -> Option<Publisher<M>> {
        match topics {
            [t] => Some(Publisher::new(M::topic(t)?.clone(), outbox.clone())),
            _ => None,
        }
    }
    fn publish(ports: &Publisher<M>, out: Option<M>, now: Nanos, origin: Option<Nanos>) {
        if let Some(m) = out {
            ports.publish(m, now, origin);
        }
    }
}

/// `Inputs` and `Outputs` for a tuple of messages, one topic each.
macro_rules! tuple_ports {
    ($($m:ident $i:tt),+) => {
        impl<$($m: Message),+> Inputs for ($($m,)+) {
            const TYPES: &'static [MsgType] = &[$($m::TYPE),+];
            type Delivered<'a> = ($(Option<&'a $m>,)+);
            type Ports = ($(InPort<$m>,)+);
            fn bind(topics: &[AnyTopic]) -> Option<Self::Ports> {
                if topics.len() != <Self as Inputs>::TYPES.len() {
                    return None;
                }
                Some(($(InPort::new(&topics[$i])?,)+))
            }
            fn read(ports: &mut Self::Ports, now: Nanos) -> Self::Delivered<'_> {
                ($(ports.$i.read(now),)+)
            }
            fn oldest_origin(ports: &Self::Ports) -> Option<Nanos> {
                [$(ports.$i.origin),+].into_iter().flatten().min()
            }
        }

        impl<$($m: Message),+> Outputs for ($($m,)+) {
            const TYPES: &'static [MsgType] = &[$($m::TYPE),+];
            type Published = ($(Option<$m>,)+);
            type Ports = ($(Publisher<$m>,)+);
            fn bind(topics: &[AnyTopic], outbox: &Outbox) -> Option<Self::Ports> {
                if topics.len() != <Self as Outputs>::TYPES.len() {
                    return None;
                }
                Some(($(Publisher::new($m::topic(&topics[$i])?.clone(), outbox.clone()),)+))
            }
            fn publish(ports: &Self::Ports, out: Self::Published, now: Nanos, origin: Option<Nanos>) {
                $(if let Some(m) = out.$i {
                    ports.$i.publish(m, now, origin);
                })+
            }
        }
    };
}

tuple_ports!(A 0, B 1);
tuple_ports!(A 0, B 1, C 2);
tuple_ports!(A 0, B 1, C 2, D 3);

/// A node of a registered kind: typed inputs and outputs (one message type, a tuple of
/// them, or `()`), as copper-rs's `CuTask`.
pub trait RustNode: Send + 'static {
    /// What it reads: a [`Message`] type, a tuple of two to four, or `()`.
    type Input: Inputs;
    /// What it publishes: a [`Message`] type, a tuple of two to four, or `()`.
    type Output: Outputs;
    /// One tick at run time `now`. `input` is, per input, the message its topic delivered
    /// since the last tick (`None`: nothing new): `Option<&M>` for one input. What it
    /// returns (per output, `Option<M>` for one) is published now.
    fn tick(
        &mut self,
        now: Nanos,
        input: <Self::Input as Inputs>::Delivered<'_>,
    ) -> <Self::Output as Outputs>::Published;
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

type Make = dyn Fn(&NodeContext<'_>, &[AnyTopic], &[AnyTopic], &Outbox) -> Result<Box<dyn Tick>, String>
    + Send
    + Sync;

struct Entry {
    inputs: &'static [MsgType],
    outputs: &'static [MsgType],
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
    let make =
        move |cx: &NodeContext<'_>, inputs: &[AnyTopic], outputs: &[AnyTopic], outbox: &Outbox| {
            let (Some(inputs), Some(outputs)) = (
                <N::Input as Inputs>::bind(inputs),
                <N::Output as Outputs>::bind(outputs, outbox),
            ) else {
                // The graph file's types were checked against the kind's when it was read.
                return Err(format!("node '{}': its topics' types changed", cx.name));
            };
            let node = make(cx)?;
            Ok(Box::new(Bound::<N> {
                node,
                inputs,
                outputs,
            }) as Box<dyn Tick>)
        };
    reg.insert(
        kind.to_string(),
        Entry {
            inputs: <N::Input as Inputs>::TYPES,
            outputs: <N::Output as Outputs>::TYPES,
            make: Box::new(make),
        },
    );
    Ok(())
}

/// The message types registered kind `kind` reads and publishes, in order (one topic
/// each), if it is registered.
pub fn shape(kind: &str) -> Option<(&'static [MsgType], &'static [MsgType])> {
    let reg = registry().read().unwrap_or_else(|e| e.into_inner());
    reg.get(kind).map(|e| (e.inputs, e.outputs))
}

/// Every registered kind's name, sorted.
pub fn kinds() -> Vec<String> {
    let reg = registry().read().unwrap_or_else(|e| e.into_inner());
    reg.keys().cloned().collect()
}

/// Make a node of registered kind `kind`, bound to `inputs` and `outputs` (the graph
/// file's, in order; published through the node's `outbox`).
///
/// # Errors
/// A one-line reason: the kind is not registered in this process, or its maker refused
/// the node's parameters.
pub(crate) fn make(
    kind: &str,
    cx: &NodeContext<'_>,
    inputs: &[AnyTopic],
    outputs: &[AnyTopic],
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
    (entry.make)(cx, inputs, outputs, outbox)
}

/// A node with its topics and what it has been given.
struct Bound<N: RustNode> {
    node: N,
    inputs: <N::Input as Inputs>::Ports,
    outputs: <N::Output as Outputs>::Ports,
}

impl<N: RustNode> Tick for Bound<N> {
    fn tick(&mut self, now: Nanos) {
        let delivered = <N::Input as Inputs>::read(&mut self.inputs, now);
        let out = self.node.tick(now, delivered);
        // The oldest origin its inputs delivered; a source's data begins at its tick.
        let origin = if <N::Input as Inputs>::TYPES.is_empty() {
            Some(now)
        } else {
            <N::Input as Inputs>::oldest_origin(&self.inputs).or(Some(now))
        };
        <N::Output as Outputs>::publish(&self.outputs, out, now, origin);
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
        assert_eq!(
            shape("echo_unit"),
            Some((&[MsgType::Force][..], &[MsgType::Force][..]))
        );
        assert!(kinds().contains(&"echo_unit".to_string()));
        assert_eq!(shape("nobody"), None);
    }

    /// Two inputs, two outputs: a force passed on, and the position it was given echoed.
    struct Mix;
    impl RustNode for Mix {
        type Input = (ForceMsg, PositionMsg);
        type Output = (ForceMsg, PositionMsg);
        fn tick(
            &mut self,
            _now: Nanos,
            (force, position): (Option<&ForceMsg>, Option<&PositionMsg>),
        ) -> (Option<ForceMsg>, Option<PositionMsg>) {
            (force.copied(), position.copied())
        }
    }

    #[test]
    fn a_node_of_several_inputs_and_outputs_passes_on_the_oldest_origin() {
        register("mix_bound", |_: &NodeContext<'_>| Ok(Mix)).unwrap();
        assert_eq!(
            shape("mix_bound"),
            Some((
                &[MsgType::Force, MsgType::Position][..],
                &[MsgType::Force, MsgType::Position][..]
            ))
        );
        let topic = |name: &str, m: MsgType| AnyTopic::new(name, m, 1).unwrap();
        let inputs = [topic("/f", MsgType::Force), topic("/p", MsgType::Position)];
        let outputs = [
            topic("/f2", MsgType::Force),
            topic("/p2", MsgType::Position),
        ];
        let params = toml::Table::new();
        let cx = NodeContext {
            name: "m",
            period: Nanos(20),
            seed: 0,
            params: &params,
        };
        // The wrong number of topics is refused (the graph file is checked before).
        assert!(make("mix_bound", &cx, &inputs[..1], &outputs, &Outbox::new()).is_err());
        let mut node = make("mix_bound", &cx, &inputs, &outputs, &Outbox::new()).unwrap();
        let (AnyTopic::Force(f), AnyTopic::Position(p)) = (&inputs[0], &inputs[1]) else {
            unreachable!()
        };
        let (AnyTopic::Force(f2), AnyTopic::Position(p2)) = (&outputs[0], &outputs[1]) else {
            unreachable!()
        };
        let at = |x| PositionMsg {
            cart_pos_m: x,
            pole_angle_rad: 0.0,
        };
        f.publish(ForceMsg { newtons: 1.0 }, Nanos(8), Some(Nanos(7)));
        p.publish(at(0.5), Nanos(3), None); // its own stamp is its origin
        node.tick(Nanos(10));
        let (mf, mp) = (f2.read(Nanos(10)).unwrap(), p2.read(Nanos(10)).unwrap());
        assert_eq!((mf.data.newtons, mp.data.cart_pos_m), (1.0, 0.5));
        assert_eq!(
            (mf.origin_stamp, mp.origin_stamp),
            (Some(Nanos(3)), Some(Nanos(3)))
        );
        // Only the force is new: only it is published, still with the older origin.
        f.publish(ForceMsg { newtons: 2.0 }, Nanos(28), Some(Nanos(27)));
        node.tick(Nanos(30));
        assert_eq!(f2.read(Nanos(30)).unwrap().origin_stamp, Some(Nanos(3)));
        assert_eq!(p2.stats().published, 1);
        // A newer position: now the force's origin (27) is the oldest.
        p.publish(at(0.7), Nanos(45), None);
        node.tick(Nanos(50));
        assert_eq!(p2.read(Nanos(50)).unwrap().origin_stamp, Some(Nanos(27)));
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
        let (inputs, outputs) = ([input.clone()], [output.clone()]);
        let mut node = make("echo_bound", &cx, &inputs, &outputs, &Outbox::new()).unwrap();
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
        assert!(make("nobody", &cx, &inputs, &outputs, &Outbox::new())
            .err()
            .unwrap()
            .contains("kind 'nobody' is not registered"));
    }
}
