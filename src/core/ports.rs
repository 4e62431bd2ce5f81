//! A node written in Rust, as the registry of node kinds takes it: [`RustNode`], with typed
//! inputs and outputs ([`Inputs`], [`Outputs`]) — one [`Message`] type, a tuple of two to
//! four, or `()` — as copper-rs's `CuTask` has them. How a kind is registered and how its
//! ticks read and publish: `ratelab::graph::registry`.

use crate::msg::{AnyTopic, Message, MsgType};
use crate::publisher::{Outbox, Publisher};
use crate::time::Nanos;
use crate::topic::Subscription;
use std::sync::Arc;

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
    topic: Arc<Subscription<M>>,
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
            topic: t.typed::<M>()?.clone(),
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
                Some(($(topics[$i].publisher::<$m>(outbox)?,)+))
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
