//! The one trait a node is written to: [`RustNode`], with typed inputs and outputs
//! ([`Inputs`], [`Outputs`]) — one [`Message`] type, a tuple of two to four, or `()` — as
//! copper-rs's `CuTask` has them. Every node kind implements it: the built-in ones
//! (`ratelab::graph::nodes`), a program's own, and the adapters of code that lives
//! elsewhere (a Python node, a ROS 2 node's proxy), whose topics are [`AnyPorts`]. How a kind
//! is registered and how its ticks read and publish: `ratelab::graph::registry`.
//!
//! An input slot is a message type `M` (a tick is given each new message once) or
//! [`Held<M>`] (a tick is given what the topic's read gives at every tick, stale reads
//! included, with the message's stamps: the zero-order hold the chapter's nodes keep).

use crate::msg::{AnyTopic, Message, MsgType};
use crate::node::{Flow, NodeState};
use crate::publisher::{Outbox, Publisher};
use crate::time::Nanos;
use crate::topic::Subscription;
use std::marker::PhantomData;
use std::sync::Arc;

/// A published message with its stamps, as a topic's read gives it (`ratelab::topic`).
pub type Stamped<M> = crate::topic::Message<M>;

/// An input slot that gives a tick what its topic's read gives at every tick: the newest
/// message (or the oldest unread, by the topic's QoS), or, when nothing new came, the
/// newest one already read that is still buffered (a stale read: compare
/// [`Stamped::seq`]); `None` only before the first message or when every buffered one
/// expired (lifespan). With its stamps ([`Stamped`]): when it
/// was published, and the origin of the reading it derives from. The chapter's nodes read
/// this way (a policy acts on the last state it has; the actuator holds the last force).
pub struct Held<M>(PhantomData<fn() -> M>);

/// Where an input stands between ticks: the `seq` of the last message that was new to it
/// and that message's origin stamp (its own stamp when it has none). Part of a node's captured
/// state (`RustNode::save`).
pub type Mark = (Option<u64>, Option<Nanos>);

/// The two kinds of input slot, and no others (ratelab reads them: a slot of one's own
/// could not be read).
mod sealed {
    pub trait Sealed {}
    impl<M: crate::msg::Message> Sealed for M {}
    impl<M: crate::msg::Message> Sealed for super::Held<M> {}
}

/// One input slot of a node: a message type `M` (each new message once) or [`Held<M>`];
/// sealed, as these two are all ratelab reads.
pub trait InputSlot: sealed::Sealed + 'static {
    /// What a tick is given.
    type Delivered<'a>;
    /// Read at `now` (ratelab's side).
    #[doc(hidden)]
    fn read(port: &mut InPort<Self::Msg>, now: Nanos) -> Self::Delivered<'_>;
    /// The message type its topic carries.
    type Msg: Message;
}

impl<M: Message> InputSlot for M {
    type Delivered<'a> = Option<&'a M>;
    type Msg = M;
    fn read(port: &mut InPort<M>, now: Nanos) -> Option<&M> {
        port.read(now).filter(|(new, _)| *new).map(|(_, m)| &m.data)
    }
}

impl<M: Message> InputSlot for Held<M> {
    type Delivered<'a> = Option<&'a Stamped<M>>;
    type Msg = M;
    fn read(port: &mut InPort<M>, now: Nanos) -> Option<&Stamped<M>> {
        port.read(now).map(|(_, m)| m)
    }
}

/// What a registered node reads: one input slot ([`InputSlot`]: a [`Message`] type or
/// [`Held`] of one), a tuple of two to four (one topic each, in the graph file's
/// `subscribes` order), `()` for none (a source), or [`AnyPorts`].
///
/// A tick is given [`Inputs::Delivered`]: per input, what its slot delivers — `Option<&M>`
/// for an input of `M` (`None`: nothing new since the last tick), `Option<&Stamped<M>>`
/// for [`Held<M>`] — one of them for one input, a tuple of them for several, `()` for none.
pub trait Inputs: 'static {
    /// The message types, in order (none for [`AnyPorts`]).
    const TYPES: &'static [MsgType];
    /// Any topics, of any type, read by the node itself ([`AnyPorts`]).
    const OPEN: bool = false;
    /// What a tick is given.
    type Delivered<'a>;
    /// The inputs bound to their topics (ratelab's side: write an `Inputs` type, not this).
    #[doc(hidden)]
    type Ports: Send;
    /// Where the inputs stand, per input ([`Mark`]).
    #[doc(hidden)]
    type Marks: Clone + Send + Sync + 'static;
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
    /// Where the inputs stand now.
    #[doc(hidden)]
    fn marks(ports: &Self::Ports) -> Self::Marks;
    /// Put the inputs back where [`Inputs::marks`] said.
    #[doc(hidden)]
    fn set_marks(ports: &mut Self::Ports, marks: &Self::Marks);
    /// Let go of what the tick was given (a frame's buffer is not held between ticks).
    #[doc(hidden)]
    fn release(_ports: &mut Self::Ports) {}
}

/// What a registered node publishes: one [`Message`] type, a tuple of two to four (one
/// topic each, in the graph file's `publishes` order), `()` for none, or [`AnyPorts`].
///
/// A tick returns [`Outputs::Published`]: per output, the message to publish now, if any —
/// `Option<M>` for one output, a tuple of them for several, `()` for none.
pub trait Outputs: 'static {
    /// The message types, in order (none for [`AnyPorts`]).
    const TYPES: &'static [MsgType];
    /// Any topics, of any type, published by the node itself ([`AnyPorts`]).
    const OPEN: bool = false;
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

/// Any topics, of any type, in and out: the ports of an adapter whose own code reads and
/// publishes them (a Python node, a ROS 2 node's proxy), through the topics and the outbox
/// its maker is given (a kind registered with `register_kind`, whose `make` is given the
/// whole `BuildContext`). A tick is given `()` and returns `()`.
pub struct AnyPorts;

impl Inputs for AnyPorts {
    const TYPES: &'static [MsgType] = &[];
    const OPEN: bool = true;
    type Delivered<'a> = ();
    type Ports = ();
    type Marks = ();
    fn bind(_: &[AnyTopic]) -> Option<()> {
        Some(())
    }
    fn read(_: &mut (), _: Nanos) {}
    fn oldest_origin(_: &()) -> Option<Nanos> {
        None
    }
    fn marks(_: &()) {}
    fn set_marks(_: &mut (), _: &()) {}
}

impl Outputs for AnyPorts {
    const TYPES: &'static [MsgType] = &[];
    const OPEN: bool = true;
    type Published = ();
    type Ports = ();
    fn bind(_: &[AnyTopic], _: &Outbox) -> Option<()> {
        Some(())
    }
    fn publish(_: &(), _: (), _: Nanos, _: Option<Nanos>) {}
}

/// One input bound to its topic, with what it delivered last.
#[doc(hidden)]
pub struct InPort<M: Message> {
    topic: Arc<Subscription<M>>,
    /// `seq` of the newest message delivered.
    last_seq: Option<u64>,
    /// Origin stamp of the newest message delivered (its own stamp when it has none).
    origin: Option<Nanos>,
    /// What the read at this tick gave.
    fresh: Option<Stamped<M>>,
}

impl<M: Message> InPort<M> {
    fn new(t: &AnyTopic) -> Option<InPort<M>> {
        Some(InPort {
            topic: t.typed::<M>()?.clone(),
            last_seq: None,
            origin: None,
            fresh: None,
        })
    }

    /// Read at `now`: what the topic's read gives, and whether it is new since the last
    /// read that delivered one.
    fn read(&mut self, now: Nanos) -> Option<(bool, &Stamped<M>)> {
        self.fresh = self.topic.read(now);
        let m = self.fresh.as_ref()?;
        let new = self.last_seq != Some(m.seq);
        if new {
            self.last_seq = Some(m.seq);
            self.origin = Some(m.origin_stamp.unwrap_or(m.stamp));
        }
        Some((new, m))
    }

    fn mark(&self) -> Mark {
        (self.last_seq, self.origin)
    }

    fn set_mark(&mut self, (last_seq, origin): Mark) {
        (self.last_seq, self.origin) = (last_seq, origin);
    }
}

impl Inputs for () {
    const TYPES: &'static [MsgType] = &[];
    type Delivered<'a> = ();
    type Ports = ();
    type Marks = ();
    fn bind(topics: &[AnyTopic]) -> Option<()> {
        topics.is_empty().then_some(())
    }
    fn read(_: &mut (), _: Nanos) {}
    fn oldest_origin(_: &()) -> Option<Nanos> {
        None
    }
    fn marks(_: &()) {}
    fn set_marks(_: &mut (), _: &()) {}
}

impl<S: InputSlot> Inputs for S {
    const TYPES: &'static [MsgType] = &[<S::Msg as Message>::TYPE];
    type Delivered<'a> = S::Delivered<'a>;
    type Ports = InPort<S::Msg>;
    type Marks = Mark;
    fn bind(topics: &[AnyTopic]) -> Option<InPort<S::Msg>> {
        match topics {
            [t] => InPort::new(t),
            _ => None,
        }
    }
    fn read(ports: &mut InPort<S::Msg>, now: Nanos) -> S::Delivered<'_> {
        S::read(ports, now)
    }
    fn oldest_origin(ports: &InPort<S::Msg>) -> Option<Nanos> {
        ports.origin
    }
    fn marks(ports: &InPort<S::Msg>) -> Mark {
        ports.mark()
    }
    fn set_marks(ports: &mut InPort<S::Msg>, marks: &Mark) {
        ports.set_mark(*marks);
    }
    fn release(ports: &mut InPort<S::Msg>) {
        ports.fresh = None;
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
            [t] => t.publisher::<M>(outbox),
            _ => None,
        }
    }
    fn publish(ports: &Publisher<M>, out: Option<M>, now: Nanos, origin: Option<Nanos>) {
        if let Some(m) = out {
            ports.publish(m, now, origin);
        }
    }
}

/// `Inputs` and `Outputs` for a tuple of slots and of messages, one topic each.
macro_rules! tuple_ports {
    ($($m:ident $i:tt),+) => {
        impl<$($m: InputSlot),+> Inputs for ($($m,)+) {
            const TYPES: &'static [MsgType] = &[$(<$m::Msg as Message>::TYPE),+];
            type Delivered<'a> = ($($m::Delivered<'a>,)+);
            type Ports = ($(InPort<$m::Msg>,)+);
            type Marks = ($(tuple_ports!(@mark $m),)+);
            fn bind(topics: &[AnyTopic]) -> Option<Self::Ports> {
                if topics.len() != <Self as Inputs>::TYPES.len() {
                    return None;
                }
                Some(($(InPort::new(&topics[$i])?,)+))
            }
            fn read(ports: &mut Self::Ports, now: Nanos) -> Self::Delivered<'_> {
                ($($m::read(&mut ports.$i, now),)+)
            }
            fn oldest_origin(ports: &Self::Ports) -> Option<Nanos> {
                [$(ports.$i.origin),+].into_iter().flatten().min()
            }
            fn marks(ports: &Self::Ports) -> Self::Marks {
                ($(ports.$i.mark(),)+)
            }
            fn set_marks(ports: &mut Self::Ports, marks: &Self::Marks) {
                $(ports.$i.set_mark(marks.$i);)+
            }
            fn release(ports: &mut Self::Ports) {
                $(ports.$i.fresh = None;)+
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
                Some(($(topics[$i].publisher::<$m>(outbox)?,)+))
            }
            fn publish(ports: &Self::Ports, out: Self::Published, now: Nanos, origin: Option<Nanos>) {
                $(if let Some(m) = out.$i {
                    ports.$i.publish(m, now, origin);
                })+
            }
        }
    };
    (@mark $m:ident) => { Mark };
}

tuple_ports!(A 0, B 1);
tuple_ports!(A 0, B 1, C 2);
tuple_ports!(A 0, B 1, C 2, D 3);

/// A node: typed inputs and outputs (an input slot, a tuple of them, `()`, or
/// [`AnyPorts`]), one `tick`, as copper-rs's `CuTask`. Every node kind is one — the built-in
/// kinds, a program's own and the adapters of Python and ROS 2 nodes — registered the same
/// way (`ratelab::graph::registry`).
///
/// Only `tick` must be written. The rest say what a node may also do: keep state a capture
/// can take and give back ([`RustNode::save`], [`RustNode::load`]; without it a capture of
/// its graph is a replay), stop the run ([`RustNode::flow`]), or be alive by what arrives
/// rather than by ticking ([`RustNode::alive_by_ticking`]).
pub trait RustNode: Send + 'static {
    /// What it reads: an [`InputSlot`] (a [`Message`] type or [`Held`] of one), a tuple of
    /// two to four, `()`, or [`AnyPorts`].
    type Input: Inputs;
    /// What it publishes: a [`Message`] type, a tuple of two to four, `()`, or [`AnyPorts`].
    type Output: Outputs;
    /// One tick at run time `now`. `input` is, per input, what its slot delivered:
    /// `Option<&M>` for an input of `M` (`None`: nothing new since the last tick). What it
    /// returns (per output, `Option<M>` for one) is published now, carrying the oldest
    /// origin among the newest messages its inputs delivered (a message without an origin
    /// counts from its own stamp; its tick time before any, and always for a source).
    ///
    /// # Panics
    /// A node whose code failed (a Python callback raised) panics with its one-line
    /// reason; the scheduler catches it and ends the run as "node X failed".
    fn tick(
        &mut self,
        now: Nanos,
        input: <Self::Input as Inputs>::Delivered<'_>,
    ) -> <Self::Output as Outputs>::Published;

    /// Asked after every tick: [`Flow::Stop`] ends the whole run (the actuator's, when the
    /// pole falls or a deadline's reaction is to stop). [`Flow::Continue`] by default.
    fn flow(&self) -> Flow {
        Flow::Continue
    }

    /// Does a tick assert the node's liveliness (ROS 2's automatic liveliness)? Yes by
    /// default; a ROS 2 node's proxy ticks whether or not the node is there, and asserts
    /// it when a message arrives instead.
    fn alive_by_ticking(&self) -> bool {
        true
    }

    /// The node's own state now, between two ticks: what it needs to go on from there as
    /// if it had never stopped (its inputs' positions are kept apart), or `None` (the
    /// default) when it cannot say, which makes a capture of its graph a replay
    /// (`ratelab::runcore`). A node that keeps nothing between ticks returns
    /// `Some(Box::new(()))`.
    fn save(&self) -> Option<NodeState> {
        None
    }

    /// Take back what [`RustNode::save`] gave; false (nothing changed) when it is not this
    /// node's.
    fn load(&mut self, _state: &NodeState) -> bool {
        false
    }
}
