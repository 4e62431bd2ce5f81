//! The **external** node's stand-in inside the graph: a node of `kind = "external"` is run by
//! another program over ROS 2 (`ratelab::ros2::external` connects it), and this proxy is
//! where its messages enter ratelab's topics.
//!
//! On each tick at run time `t` the proxy reads its input topic as a built-in node of its
//! place would (so the topic's counters and drop rule are the same), then:
//! - **virtual clock (lockstep)**: it tells ROS 2 the time is `t` (`/clock`, after every
//!   message the nodes ranked before it published at `t`) and waits, up to the node's
//!   `tick_timeout`, for the external node's one message on its output; that message is
//!   published at `t`. Nothing in time: the tick is counted as missed and publishes nothing.
//!   The contract: **one message per output per tick**, computed from what the node had
//!   received when `/clock` reached `t`. A message already waiting when a tick begins (late
//!   after a miss, or a second one for a tick) is dropped and counted, so it cannot shift
//!   the ticks after it (a second message arriving after the next tick began is taken as
//!   that tick's: nothing can tell them apart).
//! - **real clock**: it publishes, stamped `t`, every message that arrived since its last
//!   tick (so a message enters the graph at most one proxy period after it arrived: give the
//!   node a `rate_hz` at least its own).
//!
//! A published message carries the origin stamp of the newest input the proxy read (its
//! tick time before the first), so the actuator measures sense→act latency across the
//! external node as across any node. The node counts as alive (its liveliness asserted)
//! when it delivers.

use crate::graph::kind::{Code, KindDef, ParamDef, Params, Ports};
use crossbeam_channel::{Receiver, RecvTimeoutError, Sender, TrySendError};
use ratelab_core::ids::{NodeId, TopicId};
use ratelab_core::msg::{AnyTopic, MsgData};
use ratelab_core::ports::{AnyPorts, RustNode};
use ratelab_core::publisher::Outbox;
use ratelab_core::qos::Liveliness;
use ratelab_core::time::Nanos;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, OnceLock};

/// Its parameters: how long ratelab waits for the ROS 2 node.
pub const PARAMS: &[ParamDef] = &[
    ParamDef {
        name: "appear_timeout_s",
        unit: "s",
        doc: "how long to wait, before the run, for the node's liveliness tokens",
        default: 10.0,
        min: 0.0,
        max: 600.0,
    },
    ParamDef {
        name: "tick_timeout_ms",
        unit: "ms",
        doc: "virtual clock: how long (wall time) a tick waits for the node's message",
        default: 2000.0,
        min: 1.0,
        max: 60_000.0,
    },
];

/// The kind: at most one input, exactly one output, any types (each with a ROS 2 type);
/// a ROS 2 node's code.
pub fn def() -> KindDef {
    KindDef {
        doc: "a ROS 2 node fills it over --ros2; ratelab runs its proxy",
        ports: Ports::Open {
            max_inputs: 1,
            min_outputs: 1,
            max_outputs: 1,
        },
        code: Code::Ros2,
        params: Params::Numbers(PARAMS),
        ..KindDef::of("external", |cx| {
            let port = cx
                .adapter
                .attachment
                .take()
                .and_then(|a| a.downcast::<ExternalPort>().ok())
                .ok_or_else(|| format!("external node '{}' has no port", cx.node.name))?;
            Ok(External {
                port,
                input: cx.node.inputs.first().cloned(),
                output: cx
                    .node
                    .outputs
                    .first()
                    .cloned()
                    .ok_or("an external node publishes one topic")?,
                outbox: cx.outbox.clone(),
                liveliness: cx.adapter.liveliness.clone(),
                origin: None,
            })
        })
    }
}

/// How long ratelab waits for a `kind = "external"` node (`ratelab::ros2::external`), from
/// the graph file's `params = { appear_timeout_s = …, tick_timeout_ms = … }` ([`PARAMS`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExternalNodeSpec {
    /// How long to wait, before the run starts, for the node's liveliness tokens (its node
    /// and each declared endpoint) on the ROS 2 domain; default 10 s, at most 600 s.
    pub appear_timeout: Nanos,
    /// Under the virtual clock, how long (wall time) one tick waits for the node's message
    /// on each of its outputs before the tick is counted as missed; default 2 s, 1 ms to
    /// 60 s.
    pub tick_timeout: Nanos,
}

impl Default for ExternalNodeSpec {
    fn default() -> Self {
        ExternalNodeSpec::from_params(&toml::Table::new())
    }
}

impl ExternalNodeSpec {
    /// The waits a node's checked parameters give (defaults where absent).
    pub fn from_params(params: &toml::Table) -> ExternalNodeSpec {
        let get = |i: usize, scale: f64| {
            let d = &PARAMS[i];
            let x =
                crate::graph::kind::param_f64("", params, d.name, d.default).unwrap_or(d.default);
            Nanos((x.clamp(d.min, d.max) * scale).round() as u64)
        };
        ExternalNodeSpec {
            appear_timeout: get(0, 1e9),
            tick_timeout: get(1, 1e6),
        }
    }
}

/// Messages from the external node waiting for the proxy, at most; more are dropped and
/// counted ([`ExternalStats::overflow`]). Fewer for a type of large messages: see
/// [`MAX_INBOX_BYTES`].
pub const INBOX_CAPACITY: usize = 1024;

/// The most bytes of messages from the external node that may wait for the proxy, counting
/// each at its type's largest (`RosCodec::max_bytes`): 256 MiB, so an image topic waits at
/// most 4 frames of 64 MiB, and a flood from ROS 2 cannot grow memory past it. At least 2
/// messages always wait.
pub const MAX_INBOX_BYTES: usize = 256 << 20;

/// How many messages of at most `max_message_bytes` each the inbox holds.
pub fn inbox_capacity(max_message_bytes: usize) -> usize {
    (MAX_INBOX_BYTES / max_message_bytes.max(1)).clamp(2, INBOX_CAPACITY)
}

/// How the proxy reaches the ROS 2 side, set once it is connected.
pub struct ExternalLink {
    /// Lockstep (virtual clock): wait for one message per tick.
    pub lockstep: bool,
    /// Tell ROS 2 the run's time reached this (`/clock`), in order after what the graph
    /// published before.
    pub announce: Box<dyn Fn(Nanos) + Send + Sync>,
}

/// What an external node did in a run.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExternalStats {
    /// Messages it delivered into the graph.
    pub delivered: u64,
    /// Lockstep ticks that waited `tick_timeout` in vain.
    pub missed: u64,
    /// Lockstep: messages found waiting when a tick began, so not answers to it (late after
    /// a miss, or a second message for a tick): dropped, so that a late or extra message
    /// cannot shift every tick after it.
    pub stray: u64,
    /// Messages dropped because the proxy's inbox was full.
    pub overflow: u64,
    /// How many messages the inbox holds ([`inbox_capacity`]).
    pub inbox: usize,
    /// Messages that did not decode as the output's type (the first reason is kept).
    pub undecodable: u64,
    /// Why the first undecodable message did not decode.
    pub first_error: Option<String>,
}

/// Where an external node's messages come in: filled by the ROS 2 side, drained by the
/// proxy. One per external node, shared ([`crate::graph::GraphHandles::external`]).
pub struct ExternalPort {
    /// The node.
    pub node: NodeId,
    /// Its name.
    pub name: String,
    /// The topic it reads, if any.
    pub input: Option<TopicId>,
    /// The topic it publishes.
    pub output: TopicId,
    /// Its waits.
    pub settings: ExternalNodeSpec,
    tx: Sender<MsgData>,
    rx: Receiver<MsgData>,
    link: OnceLock<ExternalLink>,
    delivered: AtomicU64,
    missed: AtomicU64,
    stray: AtomicU64,
    overflow: AtomicU64,
    undecodable: AtomicU64,
    first_error: OnceLock<String>,
}

impl ExternalPort {
    /// A port for node `node` (`name`), reading `input`, publishing `output`, whose
    /// messages from ROS 2 have at most `max_message_bytes` each ([`inbox_capacity`]).
    pub fn new(
        node: NodeId,
        name: &str,
        input: Option<TopicId>,
        (output, max_message_bytes): (TopicId, usize),
        settings: ExternalNodeSpec,
    ) -> ExternalPort {
        let (tx, rx) = crossbeam_channel::bounded(inbox_capacity(max_message_bytes));
        ExternalPort {
            node,
            name: name.to_string(),
            input,
            output,
            settings,
            tx,
            rx,
            link: OnceLock::new(),
            delivered: AtomicU64::new(0),
            missed: AtomicU64::new(0),
            stray: AtomicU64::new(0),
            overflow: AtomicU64::new(0),
            undecodable: AtomicU64::new(0),
            first_error: OnceLock::new(),
        }
    }

    /// Connect the port (once; a second link is ignored and `false` returned).
    pub fn connect(&self, link: ExternalLink) -> bool {
        self.link.set(link).is_ok()
    }

    /// A message from the external node: queued for the proxy's next tick, or counted when
    /// the inbox is full.
    pub fn push(&self, data: MsgData) {
        if let Err(TrySendError::Full(_)) = self.tx.try_send(data) {
            self.overflow.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// A message from the external node that did not decode: counted, the first reason kept.
    pub fn refuse(&self, reason: String) {
        self.undecodable.fetch_add(1, Ordering::Relaxed);
        let _ = self.first_error.set(reason);
    }

    /// What it did so far.
    pub fn stats(&self) -> ExternalStats {
        ExternalStats {
            delivered: self.delivered.load(Ordering::Relaxed),
            missed: self.missed.load(Ordering::Relaxed),
            stray: self.stray.load(Ordering::Relaxed),
            overflow: self.overflow.load(Ordering::Relaxed),
            inbox: self.tx.capacity().unwrap_or(INBOX_CAPACITY),
            undecodable: self.undecodable.load(Ordering::Relaxed),
            first_error: self.first_error.get().cloned(),
        }
    }
}

/// The proxy node's state.
pub struct External {
    /// Its port.
    pub port: Arc<ExternalPort>,
    /// What it reads (for the counters and the origin stamp).
    pub input: Option<AnyTopic>,
    /// Where the external node's messages go.
    pub output: AnyTopic,
    /// Its publishers' outbox.
    pub outbox: Outbox,
    /// Its liveliness: asserted when it delivers.
    pub liveliness: Arc<Liveliness>,
    /// Origin stamp of the newest input read.
    pub origin: Option<Nanos>,
}

impl External {
    /// Read the input topic (the newest message's origin is kept).
    fn read_input(&mut self, now: Nanos) {
        if let Some(m) = self.input.as_ref().and_then(|t| t.read(now)) {
            self.origin = Some(m.origin);
        }
    }

    /// Publish `data` at `now` on the output, if it is of the output's type.
    fn deliver(&mut self, data: MsgData, now: Nanos) {
        let origin = self.origin.or(Some(now));
        if self
            .output
            .publish(Some(&self.outbox), &data, now, origin)
            .is_err()
        {
            let why = format!("a message of the wrong type for {}", self.output.name());
            self.port.refuse(why);
            return;
        }
        self.port.delivered.fetch_add(1, Ordering::Relaxed);
        self.liveliness.assert_at(now);
    }
}

/// An adapter: its topics are any ([`AnyPorts`]), read and published by the proxy itself.
impl RustNode for External {
    type Input = AnyPorts;
    type Output = AnyPorts;

    fn alive_by_ticking(&self) -> bool {
        false
    }

    /// One tick at `now` (see the module's header).
    fn tick(&mut self, now: Nanos, (): ()) {
        self.read_input(now);
        let Some(link) = self.port.link.get() else {
            return; // not connected: nothing can come
        };
        if link.lockstep {
            // Anything here before this tick's /clock answers an earlier one.
            let stray = self.port.rx.try_iter().count() as u64;
            self.port.stray.fetch_add(stray, Ordering::Relaxed);
            (link.announce)(now);
            match self
                .port
                .rx
                .recv_timeout(self.port.settings.tick_timeout.to_duration())
            {
                Ok(data) => self.deliver(data, now),
                Err(RecvTimeoutError::Timeout | RecvTimeoutError::Disconnected) => {
                    self.port.missed.fetch_add(1, Ordering::Relaxed);
                }
            }
        } else {
            while let Ok(data) = self.port.rx.try_recv() {
                self.deliver(data, now);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_inbox_holds_many_small_messages_and_few_large_ones() {
        // The cartpole's types (4 KiB at most from ROS 2): the full count.
        assert_eq!(inbox_capacity(4096), INBOX_CAPACITY);
        // Images of up to 64 MiB: 4 wait, 256 MiB in all.
        assert_eq!(inbox_capacity(64 << 20), 4);
        // Never fewer than 2, whatever the bound.
        assert_eq!(inbox_capacity(usize::MAX), 2);
        assert_eq!(inbox_capacity(0), INBOX_CAPACITY);
        let port = ExternalPort::new(
            NodeId(0),
            "camera",
            None,
            (TopicId(0), 64 << 20),
            ExternalNodeSpec::default(),
        );
        assert_eq!(port.stats().inbox, 4);
        for _ in 0..6 {
            port.push(MsgData::new(ratelab_core::msg::ForceMsg { newtons: 0.0 }));
        }
        assert_eq!(port.stats().overflow, 2);
    }
}
