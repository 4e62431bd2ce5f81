//! Graph files: the node graph as data. A TOML file names the nodes (kind, rate, parameters,
//! the topics each publishes and subscribes to) and the topics (message type, history
//! depth); [`GraphSpec::parse`] reads it with `toml` + `serde`, checks every rule, and
//! computes the tie-break order. Every view of a graph (executors, metrics, recordings,
//! the lab) is built from the one [`GraphSpec`].
//!
//! ```toml
//! name = "cartpole"
//!
//! [[node]]
//! name = "sensor"
//! kind = "sensor"          # a built-in kind (`ratelab kinds` lists them) or one
//!                          # registered in Rust (crate::graph::registry)
//! rate_hz = 50
//! publishes = "/obs"
//!
//! [[topic]]
//! name = "/obs"
//! type = "state"           # state | position | force | a type registered (ratelab_core::msg)
//! depth = 1                # history depth (keep-last), ≥ 1
//! # QoS, all optional (ratelab_core::qos; ROS 2's names): history = "keep_all", delivery = "fifo",
//! # deadline_ms = 40, lifespan_ms = 60, reliability = "reliable", on_deadline_missed = "zero",
//! # durability = "transient_local",
//! # link = { loss = 0.05, delay_ms = 10, jitter_ms = 3 }
//! ```
//!
//! A node may also take a `compute_ms` and a `callback_group`, and the file
//! `[executors.NAME]` tables: `src/runtime/graph/spec/executors.rs` has their format and rules;
//! `[processes.NAME]` tables (restart a launch's process when it fails):
//! `src/runtime/graph/spec/processes.rs`; under a `[[topic]]`, `[topic.requested.NODE]`
//! tables (what that subscription requests, judged by ROS 2's QoS compatibility rules):
//! `src/runtime/graph/spec/requested.rs`. Reading a file, rule by rule, is
//! `src/runtime/graph/spec/build.rs`.
//!
//! Rules (each broken rule is a [`SpecError`] with the line and column of the culprit):
//! - at most [`MAX_NODES`](ratelab_core::limits::MAX_NODES) nodes, names unique; exactly one actuator (the kind that steps
//!   the plant: it owns the plant step and the zero-order hold);
//! - each node's `kind` is one the registry knows ([`crate::graph::registry`]: the
//!   built-in kinds and any a Rust program registered; `ratelab kinds` prints them all,
//!   with their ports), and its topics fit the kind's ports
//!   ([`crate::graph::kind::Ports`]): of a kind of fixed ports, one topic per input and
//!   output, in that order, each of a type the port accepts (a sensor publishes `state` or
//!   `position`); of a kind of open ports (a `python` node, the learner's,
//!   `ratelab::python::node`; an `external` node), any number of topics within its bounds,
//!   of any type (`subscribes = ["/obs", "/reference"]`: a topic or a list). A `python`
//!   node names its `script` (relative to the graph file) and optional `class`;
//! - a node's parameters (`params = { … }`; the built-in kinds' also as keys of the node's
//!   table, as the chapter's files write `max_force_n = 8`) are the kind's
//!   ([`crate::graph::kind::Params`]): checked numbers with defaults, or a free table for
//!   Python and Rust kinds;
//! - every topic is declared once, has exactly one publisher and any number of subscribers
//!   (each subscription has a queue of its own, as in ROS 2: the topic's depth, drop rule,
//!   link and counters per subscriber; the chapter's topics have one), and its type matches
//!   every end;
//! - rates in (0, 10 000] Hz; the actuator at the plant's 50 Hz (each tick steps 20 ms of
//!   physics); depths ≥ 1; no field the format does not know;
//! - what the queues may hold at worst — every subscription's queue of its topic's depth
//!   (and what is in flight on a link) times the largest message of the topic's type, a
//!   camera's frame at its size — at most [`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`], checked
//!   when the file is read and at every change of a depth, QoS or rate
//!   (`src/runtime/graph/spec/memory.rs`; [`GraphSpec::queue_bytes`]);
//! - QoS values in range (deadline and lifespan > 0, loss in [0, 1], …) and combined
//!   sensibly (`on_deadline_missed` only on the actuator's input and with a deadline; no
//!   reliable link that loses everything). A deadline shorter than its publisher's period
//!   is allowed (a rate change can make it so mid-run) but is reported by
//!   [`GraphSpec::qos_warnings`].
//!
//! Tie-break among nodes due at the same instant: upstream before downstream, i.e. a
//! topological order of the topic graph (publisher before subscriber; unordered nodes keep
//! file order). That reproduces the chapter's sensor < policy < actuator (ch2.8,
//! `run_virtual`'s priorities). A node's explicit `priority` (an integer, lower first)
//! overrides: nodes tick in ascending priority, a node without one taking its topological
//! position; edges into a node with an explicit priority do not order it. A cycle among
//! nodes without explicit priorities is an error.
//!
//! No shape is required beyond one actuator: the chapter's chain (sensor → policy →
//! actuator, through any estimators and pass-through nodes) is found when the graph has it
//! ([`GraphSpec::chain`]), and the chapter's shorthands apply to it; a graph without it (an
//! open-loop source driving the actuator) runs all the same and says so where a shorthand
//! is used ([`GraphSpec::chain_for`]).

mod build;
mod executors;
mod memory;
mod processes;
mod requested;

pub use executors::ExecutorSpec;
pub use processes::{RestartPolicy, MAX_RESTARTS};

use crate::plant::ACTUATOR_HZ;
use ratelab_core::executor::ComputeTime;
use ratelab_core::qos::{
    self, Delivery, History, Link, OnDeadlineMissed, Reliability, TopicQos, MAX_DEPTH,
};
use ratelab_core::rate::period_for_hz;
use ratelab_core::time::Nanos;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

pub use ratelab_core::limits::MAX_SUBSCRIBERS;

/// A graph file larger than this is refused before it is parsed, bytes
/// ([`ratelab_core::limits::MAX_GRAPH_FILE_BYTES`]).
pub const MAX_FILE_BYTES: u64 = ratelab_core::limits::MAX_GRAPH_FILE_BYTES;

/// The chapter's graph, shipped as `graphs/cartpole.toml` and built in: the default.
pub const DEFAULT_GRAPH_TOML: &str = include_str!("../../../graphs/cartpole.toml");

/// A graph file's bytes as a launch hashes and hands them to its processes: the chapter's
/// ([`DEFAULT_GRAPH_TOML`]) when `path` is `None`, else the file, read as `--graph` reads
/// it (a regular file of at most [`MAX_FILE_BYTES`]).
///
/// # Errors
/// [`ratelab_core::input::InputError`] when the file cannot be read or is too big.
pub fn graph_file_bytes(path: Option<&Path>) -> Result<Vec<u8>, ratelab_core::input::InputError> {
    match path {
        None => Ok(DEFAULT_GRAPH_TOML.as_bytes().to_vec()),
        Some(p) => ratelab_core::input::read_regular_file(p, MAX_FILE_BYTES),
    }
}
/// The name the built-in default graph is reported under.
pub const DEFAULT_GRAPH_ORIGIN: &str = "graphs/cartpole.toml";

use crate::graph::kind::Params;
pub use crate::graph::kind::{Code, Kind, Plant, PythonCode};

pub use ratelab_core::msg::MsgType;

/// The process that holds the plant's nodes by default ([`GraphSpec::process_of`]).
pub const DEFAULT_ROBOT_PROCESS: &str = "robot";

pub use ratelab_core::ids::{NodeId, TopicId};

/// One node of a validated graph.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeSpec {
    /// Unique name.
    pub name: String,
    /// What it is: its kind's one definition ([`crate::graph::kind::KindDef`]).
    pub kind: Kind,
    /// Rate at the start of a run, Hz, in (0, 10 000].
    pub rate_hz: f64,
    /// The explicit tie-break priority, if the file gave one.
    pub priority: Option<i64>,
    /// The topics it reads, in the file's order (as many as its kind's ports take).
    pub subscribes: Vec<TopicId>,
    /// The topics it publishes, in the file's order.
    pub publishes: Vec<TopicId>,
    /// Its parameters (`params = { … }`): for a kind of numeric parameters, every one it
    /// declares, checked, defaults filled in (as floats); for a Python or Rust kind, the
    /// file's table as given.
    pub params: toml::Table,
    /// Its liveliness lease: not heard from (not ticked) for longer than this, it is
    /// reported *not alive* (ROS 2's liveliness lease duration). `None`: not monitored.
    pub liveliness_lease: Option<Nanos>,
    /// The process (an OS process) it runs in under `ratelab launch --processes`, as
    /// the file gave it; `None` takes the default placement ([`GraphSpec::process_of`]).
    pub process: Option<String>,
    /// A Python node's script and class; `None` for every other kind.
    pub python: Option<PythonCode>,
    /// What a tick costs ([`ratelab_core::executor`]): its outputs are published that long after
    /// it starts. `None`: nothing (outputs at once, as in the chapter).
    pub compute: Option<ComputeTime>,
    /// Its callback group, a group of the executor holding it ([`ExecutorSpec`]); `None`:
    /// a mutually exclusive group of its own.
    pub callback_group: Option<String>,
    /// When it joins the graph, run time (`start_ms`; ROS 2's *late joiner*): its first
    /// tick is then (or at its phase offset, if later), and its subscriptions come into
    /// being then, so what was published before reaches it only from a transient-local
    /// topic (its last `depth` messages). `None`: from t = 0. Never the actuator's.
    pub start: Option<Nanos>,
}

impl NodeSpec {
    /// Its kind's name, as the graph file spells it.
    pub fn kind_name(&self) -> &str {
        self.kind.as_str()
    }

    /// An external node's waits (from its parameters); `None` for every other kind.
    pub fn external(&self) -> Option<ExternalNodeSpec> {
        (self.kind.code() == Code::Ros2).then(|| ExternalNodeSpec::from_params(&self.params))
    }

    /// Numeric parameter `key` (its checked value, or the kind's default).
    pub fn param(&self, key: &str) -> Option<f64> {
        match self.params.get(key)? {
            toml::Value::Float(x) => Some(*x),
            toml::Value::Integer(i) => Some(*i as f64),
            _ => None,
        }
    }
}

pub use crate::graph::nodes::ExternalNodeSpec;

/// The most parameters a node may be given ([`ratelab_core::limits::MAX_NODE_PARAMS`]).
pub const MAX_PYTHON_PARAMS: usize = ratelab_core::limits::MAX_NODE_PARAMS;

/// One topic of a validated graph.
#[derive(Clone, Debug, PartialEq)]
pub struct TopicSpec {
    /// Name, by convention starting with `/`.
    pub name: String,
    /// Message type.
    pub msg: MsgType,
    /// History depth at the start of a run (keep-last depth, or keep-all cap), ≥ 1.
    pub depth: usize,
    /// The rest of its QoS at the start of a run ([`ratelab_core::qos`]).
    pub qos: TopicQos,
    /// The one publisher.
    pub publisher: NodeId,
    /// The subscribers, in tie-break order (none: nobody reads it). Each has a queue of its
    /// own ([`ratelab_core::msg::AnyTopic::subscription`]).
    pub subscribers: Vec<NodeId>,
    /// What subscriptions request of the publisher beyond the topic's QoS, by subscriber
    /// name (the file's `[topic.requested.NODE]`; none: every subscription accepts what is
    /// offered). A request the topic does not meet leaves that subscription unconnected
    /// ([`GraphSpec::incompatible`], `src/runtime/graph/spec/requested.rs`).
    pub requested: std::collections::BTreeMap<String, ratelab_core::qos::compat::RequestedQos>,
}

impl TopicSpec {
    /// The first subscriber (in tie-break order), if any: the chapter's topics have one.
    pub fn subscriber(&self) -> Option<NodeId> {
        self.subscribers.first().copied()
    }

    /// The node whose process keeps this topic's counters when the graph runs across
    /// processes: its subscriber (whose copy of the topic sees every message that crossed,
    /// and counts its drops, stale reads and losses; a launch keeps all of a topic's
    /// subscribers in one process), or its publisher when nobody subscribes. The merged
    /// `metrics.json`, the watcher's steps and a process's samples all take the topic from
    /// this node's process.
    pub fn holder(&self) -> NodeId {
        self.subscriber().unwrap_or(self.publisher)
    }
}

/// The chapter's roles, when a graph has them: the chain sensor → … → policy → … →
/// actuator ([`GraphSpec::chain`]). The chapter's flags (`--sensor-hz`, `--control-hz`,
/// `--break`), `metrics.json`'s flat keys (`obs_*`, `action_*`) and the lab's rate keys
/// speak of these; a graph without the chain has none of them (`--queue-depth`, every
/// topic's depth, applies to any graph).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Chain {
    /// The sensor at the head of the actuator's chain.
    pub sensor: NodeId,
    /// The policy that drives the actuator (through any safety nodes).
    pub policy: NodeId,
    /// The topic the policy reads (`/obs` in the chapter).
    pub obs: TopicId,
    /// The topic the policy publishes (`/action` in the chapter).
    pub action: TopicId,
}

/// A parsed, validated graph; nodes in tie-break order.
#[derive(Clone, Debug, PartialEq)]
pub struct GraphSpec {
    /// The graph's name.
    pub name: String,
    /// Nodes, in tie-break order ([`NodeId`] indexes this).
    pub nodes: Vec<NodeSpec>,
    /// Topics, in file order ([`TopicId`] indexes this).
    pub topics: Vec<TopicSpec>,
    /// The actuator: the one node that steps the plant.
    pub actuator: NodeId,
    /// The chapter's roles, when the graph has its chain: the actuator driven (through
    /// any pass-through nodes) by a policy whose input comes (through any estimators) from
    /// a sensor. `None`: some other shape (an open-loop source driving the actuator, a
    /// policy fed by no sensor); it runs all the same, without the chapter's shorthands.
    pub chain: Option<Chain>,
    /// The `[executors]` tables ([`ExecutorSpec`]); empty: every node on a thread of its own.
    pub executors: Vec<ExecutorSpec>,
    /// The `[processes]` tables' restart policies, by process, where not
    /// [`RestartPolicy::Never`] (`src/runtime/graph/spec/processes.rs`).
    pub restart: std::collections::BTreeMap<String, RestartPolicy>,
}

/// A graph file that cannot be used: one line `FILE:LINE:COL: reason`, or `FILE: reason`
/// for what concerns the whole file (it cannot be read).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct SpecError {
    /// The file (or what stands for it, e.g. a session log's run).
    pub origin: String,
    /// 1-based line; 0 for the whole file.
    pub line: usize,
    /// 1-based column (characters); 0 for the whole file.
    pub col: usize,
    /// What is wrong.
    pub reason: String,
}

/// A graph file `origin` that is not UTF-8 text, at its first byte that is not
/// (`FILE:LINE:COL: not UTF-8 text (byte 0xff)`).
pub fn not_utf8(origin: &str, e: ratelab_core::input::NotUtf8) -> SpecError {
    SpecError {
        origin: origin.to_string(),
        line: e.line,
        col: e.col,
        reason: format!("not UTF-8 text (byte {:#04x})", e.byte),
    }
}

/// A [`SpecError`]'s reason when the file is not there.
const NOT_FOUND: &str = "not found";

impl SpecError {
    /// Is the error that the file is not there (as opposed to a file that breaks a rule)?
    pub fn is_missing_file(&self) -> bool {
        self.line == 0 && self.reason == NOT_FOUND
    }
}

impl std::fmt::Display for SpecError {
    /// One line: the file's name and the reason may quote the file (a `class`, a `kind`, a
    /// key), so their control characters are written out ([`ratelab_core::text::printable`]).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let origin = ratelab_core::text::printable(&self.origin);
        let reason = ratelab_core::text::printable(&self.reason);
        match self.line {
            0 => write!(f, "{origin}: {reason}"),
            _ => write!(f, "{origin}:{}:{}: {reason}", self.line, self.col),
        }
    }
}

/// A change to a graph's settings that cannot be made (a `--rate`/`--depth` override, a
/// lab key): one line naming the node or topic.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct OverrideError(pub String);

// ---- the file, as serde reads it ------------------------------------------------------

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawGraph {
    name: Option<Spanned<String>>,
    #[serde(default, rename = "node")]
    nodes: Vec<Spanned<RawNode>>,
    #[serde(default, rename = "topic")]
    topics: Vec<Spanned<RawTopic>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    executors: Option<executors::RawExecutors>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    processes: Option<processes::RawProcesses>,
}

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawNode {
    name: Spanned<String>,
    kind: Spanned<String>,
    rate_hz: Spanned<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    priority: Option<Spanned<i64>>,
    /// A topic name, or a list of them (a python node may have several).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    subscribes: Option<Spanned<toml::Value>>,
    /// As `subscribes`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    publishes: Option<Spanned<toml::Value>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    noise_pos_m: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    noise_angle_rad: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    cutoff_hz: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    max_force_n: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    liveliness_lease_ms: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    start_ms: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    process: Option<Spanned<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    script: Option<Spanned<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    class: Option<Spanned<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    params: Option<Spanned<std::collections::BTreeMap<String, Spanned<toml::Value>>>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    compute_ms: Option<Spanned<toml::Value>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    callback_group: Option<Spanned<String>>,
}

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawTopic {
    name: Spanned<String>,
    #[serde(rename = "type")]
    msg: Spanned<MsgType>,
    depth: Spanned<i64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    history: Option<Spanned<History>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    delivery: Option<Spanned<Delivery>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    deadline_ms: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    lifespan_ms: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    reliability: Option<Spanned<Reliability>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    durability: Option<Spanned<ratelab_core::qos::compat::Durability>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    on_deadline_missed: Option<Spanned<OnDeadlineMissed>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    link: Option<Spanned<RawLink>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    requested: Option<requested::RawRequests>,
}

#[derive(Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct RawLink {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    loss: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    delay_ms: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    jitter_ms: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    retransmit_ms: Option<Spanned<f64>>,
}

/// Milliseconds as a graph file writes them (exact for whole microseconds).
fn nanos_ms(n: Nanos) -> f64 {
    n.0 as f64 / 1e6
}

/// Byte offset → 1-based (line, column in characters).
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = text.get(..offset).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

struct Ctx<'a> {
    origin: &'a str,
    text: &'a str,
}

impl Ctx<'_> {
    fn err(&self, span: Range<usize>, reason: impl Into<String>) -> SpecError {
        let (line, col) = line_col(self.text, span.start);
        SpecError {
            origin: self.origin.to_string(),
            line,
            col,
            reason: reason.into(),
        }
    }
}

fn check_rate_hz(hz: f64) -> Result<(), String> {
    period_for_hz(hz)
        .map(|_| ())
        .map_err(|_| format!("rate_hz {}", ratelab_core::rate::rate_rule(hz)))
}

fn check_actuator_rate(hz: f64) -> Result<(), String> {
    if hz == ACTUATOR_HZ {
        Ok(())
    } else {
        Err(format!(
"actuator rate {hz} Hz refused: it must be {ACTUATOR_HZ} Hz (one 20 ms plant step per tick)"
        ))
    }
}

/// A history depth in 1..=[`MAX_DEPTH`], any whole number given (a graph file's `i64`, a
/// flag's `usize`) said as given when refused.
fn check_depth(depth: impl Into<i128>) -> Result<usize, String> {
    let depth: i128 = depth.into();
    match usize::try_from(depth) {
        Ok(d) if (1..=MAX_DEPTH).contains(&d) => Ok(d),
        _ => Err(format!("depth must be in 1..={MAX_DEPTH}, got {depth}")),
    }
}

impl GraphSpec {
    /// The chapter's three-node graph (`graphs/cartpole.toml`, compiled in).
    pub fn chapter() -> GraphSpec {
        GraphSpec::parse(DEFAULT_GRAPH_TOML, DEFAULT_GRAPH_ORIGIN)
            .expect("the shipped default graph is valid")
    }

    /// The topic carrying the state estimate the chain's policy reads, when the chain runs
    /// through an estimator: the policy's input is of type `state` and its publisher is not
    /// the chain's sensor (the built-in estimator, a Python filter). The actuator takes that
    /// topic's newest message beside the plant's state at each tick ([`ratelab_core::estimate`]).
    pub fn estimate_topic(&self) -> Option<TopicId> {
        let c = self.chain?;
        let t = &self.topics[c.obs.0];
        (t.msg == <ratelab_core::msg::StateMsg as ratelab_core::msg::Message>::TYPE
            && t.publisher != c.sensor)
            .then_some(c.obs)
    }

    /// Read a graph file: refused when it is not a regular file or is larger than
    /// [`MAX_FILE_BYTES`], then parsed as [`GraphSpec::parse`].
    ///
    /// # Errors
    /// A [`SpecError`] (line 0, the whole file, for a file that cannot be read; at its first
    /// byte that is not, for a file that is not UTF-8).
    pub fn load(path: &Path) -> Result<GraphSpec, SpecError> {
        let origin = path.display().to_string();
        let at_start = |reason: String| SpecError {
            origin: origin.clone(),
            line: 0,
            col: 0,
            reason,
        };
        let bytes = ratelab_core::input::read_regular_file(path, MAX_FILE_BYTES).map_err(|e| {
            if matches!(e, ratelab_core::input::InputError::NotFound(_)) {
                return at_start(NOT_FOUND.into());
            }
            // The error names the file first; the line's `FILE:` already does.
            let too_large = matches!(e, ratelab_core::input::InputError::TooLarge { .. });
            let text = e.to_string();
            let prefix = format!("{origin}: ");
            let text = text.strip_prefix(&prefix).unwrap_or(&text);
            at_start(if too_large {
                ratelab_core::limits::refusal(text, "MAX_GRAPH_FILE_BYTES")
            } else {
                text.to_string()
            })
        })?;
        let text = ratelab_core::input::utf8_text(bytes).map_err(|e| not_utf8(&origin, e))?;
        GraphSpec::parse(&text, &origin)
    }

    /// Parse and validate graph-file `text`; `origin` names it in errors.
    ///
    /// # Errors
    /// The first broken rule, as a [`SpecError`] at the culprit's position.
    pub fn parse(text: &str, origin: &str) -> Result<GraphSpec, SpecError> {
        let cx = Ctx { origin, text };
        let raw: RawGraph = toml::from_str(text).map_err(|e| {
            let span = e.span().unwrap_or(0..0);
            let msg = e.message().lines().next().unwrap_or("invalid TOML").trim();
            cx.err(span, in_words(msg))
        })?;
        build::build(&cx, raw)
    }

    /// The graph as a graph file (TOML) that [`GraphSpec::parse`] reads back to an equal
    /// spec, with the current rates and depths. Session logs store this text, so a replay
    /// does not depend on the file it came from.
    pub fn to_toml(&self) -> String {
        let s = |v: String| Spanned::new(0..0, v);
        let f = |v: f64| Spanned::new(0..0, v);
        // One topic as a string (as the chapter's files write it), several as a list.
        let topic_names = |ts: &[TopicId]| -> Option<Spanned<toml::Value>> {
            let names: Vec<toml::Value> = ts
                .iter()
                .map(|t| toml::Value::String(self.topics[t.0].name.clone()))
                .collect();
            match names.len() {
                0 => None,
                1 => names.into_iter().next(),
                _ => Some(toml::Value::Array(names)),
            }
            .map(|v| Spanned::new(0..0, v))
        };
        let raw = RawGraph {
            name: Some(s(self.name.clone())),
            nodes: self
                .nodes
                .iter()
                .map(|n| {
                    // A kind's numeric parameters at their defaults are left out.
                    let defaults = match n.kind.def().params {
                        Params::Numbers(defs) => defs,
                        Params::Free => &[],
                    };
                    let params: std::collections::BTreeMap<String, Spanned<toml::Value>> = n
                        .params
                        .iter()
                        .filter(|(k, v)| {
                            !defaults
                                .iter()
                                .any(|d| d.name == k.as_str() && v.as_float() == Some(d.default))
                        })
                        .map(|(k, v)| (k.clone(), Spanned::new(0..0, v.clone())))
                        .collect();
                    Spanned::new(
                        0..0,
                        RawNode {
                            name: s(n.name.clone()),
                            kind: s(n.kind_name().to_string()),
                            rate_hz: f(n.rate_hz),
                            priority: n.priority.map(|p| Spanned::new(0..0, p)),
                            subscribes: topic_names(&n.subscribes),
                            publishes: topic_names(&n.publishes),
                            noise_pos_m: None,
                            noise_angle_rad: None,
                            cutoff_hz: None,
                            max_force_n: None,
                            liveliness_lease_ms: n.liveliness_lease.map(|l| f(nanos_ms(l))),
                            start_ms: n.start.map(|l| f(nanos_ms(l))),
                            process: n.process.clone().map(s),
                            script: n.python.as_ref().map(|p| s(p.script.clone())),
                            class: n.python.as_ref().and_then(|p| p.class.clone()).map(s),
                            params: (!params.is_empty()).then(|| Spanned::new(0..0, params)),
                            compute_ms: n
                                .compute
                                .map(|c| Spanned::new(0..0, executors::compute_value(&c))),
                            callback_group: n.callback_group.clone().map(s),
                        },
                    )
                })
                .collect(),
            topics: self
                .topics
                .iter()
                .map(|t| {
                    let q = &t.qos;
                    let d = TopicQos::default();
                    let keep = |differs: bool| differs.then_some(());
                    Spanned::new(
                        0..0,
                        RawTopic {
                            name: s(t.name.clone()),
                            msg: Spanned::new(0..0, t.msg),
                            depth: Spanned::new(0..0, t.depth as i64),
                            history: keep(q.history != d.history)
                                .map(|()| Spanned::new(0..0, q.history)),
                            delivery: keep(q.delivery != d.delivery)
                                .map(|()| Spanned::new(0..0, q.delivery)),
                            deadline_ms: q.deadline.map(|v| f(nanos_ms(v))),
                            lifespan_ms: q.lifespan.map(|v| f(nanos_ms(v))),
                            reliability: keep(q.reliability != d.reliability)
                                .map(|()| Spanned::new(0..0, q.reliability)),
                            durability: keep(q.durability != d.durability)
                                .map(|()| Spanned::new(0..0, q.durability)),
                            on_deadline_missed: keep(q.on_deadline_missed != d.on_deadline_missed)
                                .map(|()| Spanned::new(0..0, q.on_deadline_missed)),
                            link: q.link.map(|l: Link| {
                                Spanned::new(
                                    0..0,
                                    RawLink {
                                        loss: Some(f(l.loss)),
                                        delay_ms: Some(f(nanos_ms(l.delay))),
                                        jitter_ms: Some(f(nanos_ms(l.jitter))),
                                        retransmit_ms: Some(f(nanos_ms(l.retransmit))),
                                    },
                                )
                            }),
                            requested: requested::to_raw(t),
                        },
                    )
                })
                .collect(),
            executors: executors::to_raw(self),
            processes: processes::to_raw(self),
        };
        toml::to_string(&raw).expect("a graph always serializes")
    }

    /// The process (an OS process) node `id` runs in under `ratelab launch
    /// --processes`: the file's `process = "…"`, or by default `robot` for the nodes that
    /// touch the simulator (sensors and the actuator, as drivers touch hardware), for an
    /// external node (its proxy) its input's publisher's process, and the node's own name
    /// for every other node. Owned; [`GraphSpec::process_name`] borrows it.
    pub fn process_of(&self, id: NodeId) -> String {
        self.process_name(id).to_string()
    }

    /// [`GraphSpec::process_of`], borrowed from the graph: what a check of every tick
    /// report asks, without an allocation.
    pub fn process_name(&self, id: NodeId) -> &str {
        let mut at = id;
        // An external node's proxy goes with its input's publisher (through other external
        // nodes, at most once round the graph): that process offers the input to ROS 2
        // and `/clock` after it, in order (`ratelab::ros2::external`).
        for _ in 0..=self.nodes.len() {
            let n = self.node(at);
            match (&n.process, n.subscribes.first().copied()) {
                (Some(p), _) => return p,
                (None, Some(t)) if n.kind.code() == Code::Ros2 && self.topic(t).publisher != id => {
                    at = self.topic(t).publisher;
                }
                (None, _) if n.kind.plant() != Plant::None => return DEFAULT_ROBOT_PROCESS,
                (None, _) => return &n.name,
            }
        }
        &self.node(id).name
    }

    /// The placement: each process with its nodes (in tie-break order), processes in the
    /// order of their first node.
    pub fn placement(&self) -> Vec<(String, Vec<NodeId>)> {
        let mut out: Vec<(String, Vec<NodeId>)> = Vec::new();
        let mut index: std::collections::HashMap<String, usize> = Default::default();
        for i in 0..self.nodes.len() {
            let p = self.process_of(NodeId(i));
            match index.get(&p) {
                Some(&k) => out[k].1.push(NodeId(i)),
                None => {
                    index.insert(p.clone(), out.len());
                    out.push((p, vec![NodeId(i)]));
                }
            }
        }
        out
    }

    /// The node named `name`.
    pub fn node_id(&self, name: &str) -> Option<NodeId> {
        self.nodes.iter().position(|n| n.name == name).map(NodeId)
    }

    /// The first node of `kind = "external"`, if any: such a graph runs only with `--ros2`
    /// (`ratelab::ros2::external`; across processes, its proxy beside its input's
    /// publisher).
    pub fn first_external(&self) -> Option<&NodeSpec> {
        self.nodes.iter().find(|n| n.kind.code() == Code::Ros2)
    }

    /// The topic named `name`.
    pub fn topic_id(&self, name: &str) -> Option<TopicId> {
        self.topics.iter().position(|t| t.name == name).map(TopicId)
    }

    /// Node `id`.
    pub fn node(&self, id: NodeId) -> &NodeSpec {
        &self.nodes[id.0]
    }

    /// Topic `id`.
    pub fn topic(&self, id: TopicId) -> &TopicSpec {
        &self.topics[id.0]
    }

    /// Set node `name`'s rate, under the file's rules.
    ///
    /// # Errors
    /// [`OverrideError`] for an unknown node or a rate the node cannot take.
    pub fn set_rate(&mut self, name: &str, hz: f64) -> Result<(), OverrideError> {
        let id = self.known_node(name)?;
        self.set_rate_of(id, hz)
    }

    /// Node `name`'s id, or the override error naming the graph's nodes.
    ///
    /// # Errors
    /// [`OverrideError`] when the graph has no node of that name.
    pub fn known_node(&self, name: &str) -> Result<NodeId, OverrideError> {
        self.node_id(name).ok_or_else(|| {
            OverrideError(format!(
                "graph '{}' has no node '{name}' (nodes: {})",
                self.name,
                self.node_names().join(", ")
            ))
        })
    }

    /// Check that `other` is this graph but for its nodes' code and parameters (a Python
    /// node's script and class, `params`): the same nodes, kinds, rates, topics, QoS,
    /// executors and processes — what a node restarted in place needs of the graph around
    /// it (`ratelab::runcore::RunCore::restart_nodes`).
    ///
    /// # Errors
    /// A one-line description naming the first thing that differs (nodes, topics, or
    /// the rest).
    pub fn same_shape(&self, other: &GraphSpec) -> Result<(), String> {
        let blank = |g: &GraphSpec| {
            let mut g = g.clone();
            for n in &mut g.nodes {
                n.params = toml::Table::new();
                n.python = None;
            }
            g
        };
        let (a, b) = (blank(self), blank(other));
        if a == b {
            return Ok(());
        }
        let what = if a.nodes.len() != b.nodes.len() {
            "its nodes".to_string()
        } else if let Some((x, _)) = a.nodes.iter().zip(&b.nodes).find(|(x, y)| x != y) {
            format!("node '{}'", x.name)
        } else if a.topics != b.topics {
            "its topics".to_string()
        } else {
            "its settings".to_string()
        };
        Err(format!(
            "graph '{}' changed beyond its nodes' code and parameters ({what})",
            self.name
        ))
    }

    /// Topic `name`'s id, or the override error naming the graph's topics.
    fn known_topic(&self, name: &str) -> Result<TopicId, OverrideError> {
        self.topic_id(name).ok_or_else(|| {
            OverrideError(format!(
                "graph '{}' has no topic '{name}' (topics: {})",
                self.name,
                self.topics
                    .iter()
                    .map(|t| t.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })
    }

    /// Set node `id`'s rate, under the file's rules.
    ///
    /// # Errors
    /// [`OverrideError`] for a rate the node cannot take, or one that puts more messages in
    /// flight on its topics' links than [`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`] allows
    /// (nothing changes).
    pub fn set_rate_of(&mut self, id: NodeId, hz: f64) -> Result<(), OverrideError> {
        let node = &mut self.nodes[id.0];
        check_rate_hz(hz).map_err(|e| OverrideError(format!("node '{}': {e}", node.name)))?;
        if node.kind.is_actuator() {
            check_actuator_rate(hz).map_err(OverrideError)?;
        }
        let was = std::mem::replace(&mut node.rate_hz, hz);
        // A faster publisher has more messages in flight on a link (memory.rs).
        let linked = self.nodes[id.0]
            .publishes
            .iter()
            .any(|t| self.topics[t.0].qos.link.is_some());
        if linked && hz > was {
            if let Err(e) = self.check_queue_bytes() {
                self.nodes[id.0].rate_hz = was;
                return Err(OverrideError(format!(
                    "node '{}': {e}",
                    self.nodes[id.0].name
                )));
            }
        }
        Ok(())
    }

    /// Set topic `name`'s history depth.
    ///
    /// # Errors
    /// [`OverrideError`] for an unknown topic, a depth outside 1..=[`MAX_DEPTH`], or one
    /// that takes the graph's queues past [`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`] (nothing
    /// changes).
    pub fn set_depth(&mut self, name: &str, depth: usize) -> Result<(), OverrideError> {
        let id = self.known_topic(name)?;
        let d = check_depth(u64::try_from(depth).unwrap_or(u64::MAX))
            .map_err(|e| OverrideError(format!("topic '{name}': {e}")))?;
        let was = std::mem::replace(&mut self.topics[id.0].depth, d);
        if d > was {
            if let Err(e) = self.check_queue_bytes() {
                self.topics[id.0].depth = was;
                return Err(OverrideError(format!("topic '{name}': depth {d}: {e}")));
            }
        }
        Ok(())
    }

    /// Set every topic's depth (the chapter's `--queue-depth`).
    ///
    /// # Errors
    /// [`OverrideError`] for a depth outside 1..=[`MAX_DEPTH`], or one that takes the
    /// graph's queues past [`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`] (nothing changes),
    /// its line naming no setting (`depth must be in 1..=1000000, got 0`): the caller names
    /// the one it was given as (`--queue-depth`, `queue_depth`).
    pub fn set_all_depths(&mut self, depth: usize) -> Result<(), OverrideError> {
        check_depth(u64::try_from(depth).unwrap_or(u64::MAX)).map_err(OverrideError)?;
        let was: Vec<usize> = self
            .topics
            .iter_mut()
            .map(|t| std::mem::replace(&mut t.depth, depth))
            .collect();
        if let Err(e) = self.check_queue_bytes() {
            for (t, d) in self.topics.iter_mut().zip(was) {
                t.depth = d;
            }
            return Err(OverrideError(format!("depth {depth}: {e}")));
        }
        Ok(())
    }

    /// Set topic `name`'s QoS keys from a `KEY=VALUE[,KEY=VALUE…]` list (the graph file's
    /// keys; `--qos`, `--link`). All or nothing: on an error the topic is unchanged.
    ///
    /// # Errors
    /// [`OverrideError`] naming the topic for an unknown topic, key or value, a bad
    /// combination ([`qos::check_combination`]), or a depth or link that takes the graph's
    /// queues past [`ratelab_core::limits::MAX_GRAPH_QUEUE_BYTES`].
    pub fn set_qos(&mut self, name: &str, pairs: &str) -> Result<(), OverrideError> {
        let id = self.known_topic(name)?;
        let err = |e: String| OverrideError(format!("topic '{name}': {e}"));
        let t = &self.topics[id.0];
        let (mut q, mut depth) = (t.qos, t.depth);
        for (k, v) in qos::split_pairs(pairs).map_err(err)? {
            qos::apply_key(&mut q, &mut depth, k, v).map_err(err)?;
        }
        let to_actuator = t
            .subscribers
            .iter()
            .any(|n| self.nodes[n.0].kind.is_actuator());
        qos::check_combination(&q, to_actuator).map_err(err)?;
        let t = &mut self.topics[id.0];
        let was = (t.qos, t.depth);
        (t.qos, t.depth) = (q, depth);
        if let Err(e) = self.check_queue_bytes() {
            let t = &mut self.topics[id.0];
            (t.qos, t.depth) = was;
            return Err(err(e.0));
        }
        Ok(())
    }

    /// Set node `name`'s liveliness lease, ms (`--lease NODE=MS`).
    ///
    /// # Errors
    /// [`OverrideError`] for an unknown node or a lease not in (0, [`qos::MAX_QOS_MS`]].
    pub fn set_lease(&mut self, name: &str, ms: f64) -> Result<(), OverrideError> {
        let id = self.known_node(name)?;
        let lease = qos::ms_to_nanos("liveliness_lease_ms", ms, false)
            .map_err(|e| OverrideError(format!("node '{name}': {e}")))?;
        self.nodes[id.0].liveliness_lease = Some(lease);
        Ok(())
    }

    /// Settings that are allowed but probably not meant: a deadline shorter than its
    /// publisher's period misses every period; a node that runs the brain in a graph with no
    /// sensor → policy → actuator chain (it drives nothing the chapter would call control).
    /// One line each, naming the topic or node.
    pub fn qos_warnings(&self) -> Vec<String> {
        let shape = self
            .nodes
            .iter()
            .filter(|n| self.chain.is_none() && n.kind.def().uses_brain)
            .map(|n| {
                format!(
                    "warning: node '{}' runs the brain, but graph '{}' has no sensor → policy → actuator chain through it: the chapter's figures and shorthands do not apply",
                    n.name, self.name
                )
            });
        shape
            .chain(self.topics.iter().filter_map(|t| {
                let d = t.qos.deadline?;
                let p = self.nodes[t.publisher.0].rate_hz;
                let period = period_for_hz(p).ok()?;
                (d < period).then(|| {
                    format!(
                        "warning: topic '{}': deadline {d} is shorter than the period of its publisher '{}' ({period} at {p} Hz): every period will be missed",
                        t.name, self.nodes[t.publisher.0].name
                    )
                })
            }))
            .collect()
    }

    /// Node names in tie-break order.
    pub fn node_names(&self) -> Vec<&str> {
        self.nodes.iter().map(|n| n.name.as_str()).collect()
    }

    /// The chain's policy rate (the chapter's control rate), Hz; `None` without the chain.
    pub fn control_hz(&self) -> Option<f64> {
        self.chain.map(|c| self.node(c.policy).rate_hz)
    }

    /// The chain's sensor rate, Hz; `None` without the chain.
    pub fn sensor_hz(&self) -> Option<f64> {
        self.chain.map(|c| self.node(c.sensor).rate_hz)
    }

    /// The actuator's rate, Hz.
    pub fn actuator_hz(&self) -> f64 {
        self.node(self.actuator).rate_hz
    }

    /// The depth of the policy's input topic (the chapter's one queue depth), at the start;
    /// `None` without the chain.
    pub fn queue_depth(&self) -> Option<usize> {
        self.chain.map(|c| self.topic(c.obs).depth)
    }

    /// The chain, or a one-line reason naming what uses it (`--control-hz`, a lab key)
    /// when the graph has none, and what to give instead in `speech`'s words
    /// (`--rate NODE=HZ` or `rate={'NODE': HZ}`).
    ///
    /// # Errors
    /// [`OverrideError`]: the graph has no chapter chain.
    pub fn chain_for(
        &self,
        what: &str,
        speech: crate::setting::Speech,
    ) -> Result<Chain, OverrideError> {
        let instead = match speech {
            crate::setting::Speech::Flags => "--rate NODE=HZ, --depth TOPIC=N",
            crate::setting::Speech::Keywords => "rate={'NODE': HZ}, depth={'TOPIC': N}",
        };
        self.chain.ok_or_else(|| {
            OverrideError(format!(
                "{what} speaks of the chapter's chain (sensor → policy → actuator), which graph '{}' does not have: name a node or topic instead ({instead})",
                self.name
            ))
        })
    }

    /// Layers for drawing left to right: a node's layer is one more than its publishers'
    /// deepest (nodes that read nothing at 0), following subscriptions: the longest path to
    /// it, in O((nodes + subscriptions) log nodes). A cycle (possible with explicit
    /// priorities) is entered at its first node (in node order) that something laid out
    /// already feeds, which goes one past what feeds it, and the rest of the cycle follows.
    pub fn layers(&self) -> Vec<usize> {
        let n = self.nodes.len();
        let publishers = |i: usize| {
            self.nodes[i]
                .subscribes
                .iter()
                .map(|t| self.topics[t.0].publisher.0)
                .filter(move |&p| p != i)
        };
        let mut waiting: Vec<usize> = (0..n).map(|i| publishers(i).count()).collect();
        let mut downstream: Vec<Vec<usize>> = vec![Vec::new(); n];
        for i in 0..n {
            for p in publishers(i) {
                downstream[p].push(i);
            }
        }
        let mut layer = vec![0usize; n];
        let mut placed = vec![false; n];
        let mut ready: Vec<usize> = (0..n).filter(|&i| waiting[i] == 0).collect();
        // Unplaced nodes that a placed one feeds, and the first unplaced one in node order.
        let mut fed = std::collections::BTreeSet::new();
        let mut next_unplaced = 0;
        loop {
            while let Some(p) = ready.pop() {
                if std::mem::replace(&mut placed[p], true) {
                    continue;
                }
                for &s in downstream[p].iter().filter(|&&s| !placed[s]) {
                    layer[s] = layer[s].max(layer[p] + 1);
                    waiting[s] = waiting[s].saturating_sub(1);
                    if waiting[s] == 0 {
                        ready.push(s);
                    } else {
                        fed.insert(s);
                    }
                }
            }
            // Only cycles are left: enter one.
            let entry = loop {
                match fed.pop_first() {
                    Some(s) if placed[s] => continue,
                    Some(s) => break Some(s),
                    None => break None,
                }
            };
            while next_unplaced < n && placed[next_unplaced] {
                next_unplaced += 1;
            }
            match entry.or((next_unplaced < n).then_some(next_unplaced)) {
                Some(s) => ready.push(s),
                None => return layer,
            }
        }
    }
}

/// A Python identifier (ASCII): a class or parameter name.
fn valid_python_name(s: &str) -> bool {
    (1..=64).contains(&s.len())
        && !s.starts_with(|c: char| c.is_ascii_digit())
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// A node or process name: 1 to 32 letters, digits, `_` or `-` (also a key-expression chunk).
pub fn valid_node_name(s: &str) -> bool {
    (1..=32).contains(&s.len())
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// `/` then one or more names of letters, digits and `_`, separated by single `/`: as ROS 2
/// names topics, and so that no two topics map to one Zenoh key (`/a` and `/a/`, `/a//b`).
fn valid_topic_name(s: &str) -> bool {
    (2..=64).contains(&s.len())
        && s.strip_prefix('/').is_some_and(|rest| {
            rest.split('/').all(|part| {
                !part.is_empty() && part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            })
        })
}

impl fmt::Display for GraphSpec {
    /// One line: `cartpole: sensor 50 Hz → /obs → policy 50 Hz → …` in tie-break order.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:", self.name)?;
        for (i, n) in self.nodes.iter().enumerate() {
            write!(
                f,
                "{} {} {} Hz",
                if i == 0 { "" } else { " |" },
                n.name,
                n.rate_hz
            )?;
            for (k, t) in n.publishes.iter().enumerate() {
                let sep = if k == 0 { " →" } else { "," };
                write!(f, "{sep} {}", self.topics[t.0].name)?;
            }
        }
        Ok(())
    }
}

/// A TOML reader's type error in a graph file's words, not Rust's: `expected f64` is
/// `expected a number`, `expected i64` (or any integer type) `expected a whole number`,
/// `expected a sequence` `expected a list`, `expected a map` or `expected struct …`
/// `expected a table`; an integer past 64 bits (`` `1e23` as i128 ``) is `(too large)`, and
/// a `sequence` or `map` given is a list or a table. Only serde's own words are touched
/// (anchored to the backtick, comma or end around them), never a value quoted in the message.
fn in_words(msg: &str) -> String {
    // serde's own words open the message ("invalid type: integer `N` as i128, expected …",
    // "invalid type: sequence, expected …"): only there are they rewritten.
    let mut out = msg.to_string();
    if let Some(rest) = msg.strip_prefix("invalid type: integer `") {
        let digits = rest.find('`').map_or("", |end| &rest[..end]);
        for wide in ["i128", "u128"] {
            if let Some(tail) = rest.strip_prefix(&format!("{digits}` as {wide},")) {
                out = format!("invalid type: integer `{digits}` (too large),{tail}");
            }
        }
    }
    for (rust, words) in [("sequence", "a list"), ("map", "a table")] {
        if let Some(tail) = out.strip_prefix(&format!("invalid type: {rust},")) {
            out = format!("invalid type: {words},{tail}");
        }
    }
    if let Some((head, ty)) = out.rsplit_once(", expected ") {
        let words = match ty {
            "f64" | "f32" => Some("a number"),
            "i8" | "i16" | "i32" | "i64" | "i128" | "isize" => Some("a whole number"),
            "u8" | "u16" | "u32" | "u64" | "u128" | "usize" => Some("a whole number, 0 or more"),
            "a sequence" => Some("a list ([[node]] and [[topic]] are lists of tables)"),
            "a map" => Some("a table"),
            t if t.starts_with("struct ") => Some("a table"),
            _ => None,
        };
        if let Some(words) = words {
            return format!("{head}, expected {words}");
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<GraphSpec, SpecError> {
        GraphSpec::parse(text, "g.toml")
    }

    const CHAIN: &str = r#"
name = "t"
[[node]]
name = "actuator"
kind = "actuator"
rate_hz = 50
subscribes = "/action"
[[node]]
name = "policy"
kind = "policy"
rate_hz = 50
subscribes = "/obs"
publishes = "/action"
[[node]]
name = "sensor"
kind = "sensor"
rate_hz = 50
publishes = "/obs"
[[topic]]
name = "/obs"
type = "state"
depth = 1
[[topic]]
name = "/action"
type = "force"
depth = 1
"#;

    /// A value of the wrong type is said in a graph file's words, at its place (it said
    /// `expected f64`, `as i128`).
    #[test]
    fn a_value_of_the_wrong_type_is_said_in_words_not_rust_types() {
        for (from, to, said) in [
            (
                "rate_hz = 50\nsubscribes = \"/action\"",
                "rate_hz = \"fast\"\nsubscribes = \"/action\"",
                "invalid type: string \"fast\", expected a number",
            ),
            (
                "rate_hz = 50\nsubscribes = \"/action\"",
                "rate_hz = 99999999999999999999999\nsubscribes = \"/action\"",
                "invalid type: integer `99999999999999999999999` (too large), expected a number",
            ),
            (
                "rate_hz = 50\nsubscribes = \"/action\"",
                "rate_hz = [1]\nsubscribes = \"/action\"",
                "invalid type: a list, expected a number",
            ),
            (
                "type = \"state\"\ndepth = 1",
                "type = \"state\"\ndepth = \"deep\"",
                "invalid type: string \"deep\", expected a whole number",
            ),
        ] {
            assert_eq!(CHAIN.matches(from).count(), 1, "{from}");
            let e = parse(&CHAIN.replacen(from, to, 1)).unwrap_err().to_string();
            assert!(e.contains(said), "{to}: {e}");
            assert!(
                !e.contains("f64") && !e.contains("i64") && !e.contains("i128"),
                "{e}"
            );
        }
        // `[node]` where `[[node]]` makes a list of them.
        let e = parse("name = \"t\"\n[node]\nname = \"a\"\nkind = \"actuator\"\nrate_hz = 50\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("invalid type: a table, expected a list ([[node]] and [[topic]] are lists of tables)"),
            "{e}"
        );
        // A value quoted in a message is never rewritten.
        assert_eq!(
            in_words("unknown node ` as i128, x`"),
            "unknown node ` as i128, x`"
        );
    }

    #[test]
    fn the_default_graph_orders_sensor_policy_actuator() {
        let g = GraphSpec::chapter();
        assert_eq!(g.node_names(), ["sensor", "policy", "actuator"]);
        let chain = g.chain.unwrap();
        assert_eq!(chain.obs, g.topic_id("/obs").unwrap());
        assert_eq!(chain.action, g.topic_id("/action").unwrap());
        assert_eq!(g.node(g.actuator).name, "actuator");
        assert_eq!(
            (g.sensor_hz(), g.control_hz(), g.actuator_hz()),
            (Some(50.0), Some(50.0), 50.0)
        );
        assert_eq!(g.queue_depth(), Some(1));
    }

    #[test]
    fn a_topic_is_held_by_its_subscriber_else_by_its_publisher() {
        let text = format!(
            "{CHAIN}[[node]]\nname = \"cam\"\nkind = \"sensor\"\nrate_hz = 10\npublishes = \"/img\"\n\
             [[topic]]\nname = \"/img\"\ntype = \"state\"\ndepth = 1\n"
        );
        let g = parse(&text).unwrap();
        let holder = |t: &str| {
            g.node(g.topic(g.topic_id(t).unwrap()).holder())
                .name
                .clone()
        };
        assert_eq!(holder("/obs"), "policy");
        assert_eq!(holder("/action"), "actuator");
        assert_eq!(holder("/img"), "cam", "nobody subscribes: its publisher");
    }

    #[test]
    fn file_order_does_not_change_the_topological_order() {
        let g = parse(CHAIN).unwrap();
        assert_eq!(g.node_names(), ["sensor", "policy", "actuator"]);
        assert_eq!(g.layers(), vec![0, 1, 2]);
    }

    #[test]
    fn layers_are_the_longest_path_and_a_cycle_goes_past_what_feeds_it() {
        let g = parse(&crate::graph::synthetic::graph_toml(11, 1)).unwrap();
        let layer = |name: &str| g.layers()[g.node_id(name).unwrap().0];
        let chain = ["sensor", "policy", "actuator"].map(layer);
        assert_eq!(chain, [0, 1, 2]);
        for k in 0..2 {
            let controller = ["sensor", "estimator", "policy", "safety"]
                .map(|kind| layer(&format!("{kind}_{k}")));
            assert_eq!(controller, [0, 1, 2, 3], "controller {k}");
        }
        // Two Python nodes feeding each other (a priority breaks the tie-break's cycle): both
        // past the sensor that feeds the first.
        let text = format!(
            "{CHAIN}\n[[node]]\nname = \"a\"\nkind = \"python\"\nscript = \"a.py\"\nrate_hz = 10\n\
             subscribes = [\"/obs\", \"/y\"]\npublishes = \"/x\"\npriority = 5\n\
             [[node]]\nname = \"b\"\nkind = \"python\"\nscript = \"b.py\"\nrate_hz = 10\n\
             subscribes = \"/x\"\npublishes = \"/y\"\n\
             [[topic]]\nname = \"/x\"\ntype = \"state\"\ndepth = 1\n\
             [[topic]]\nname = \"/y\"\ntype = \"state\"\ndepth = 1\n"
        );
        let g = parse(&text).unwrap();
        let layers = g.layers();
        let at = |name: &str| layers[g.node_id(name).unwrap().0];
        assert_eq!(at("sensor"), 0);
        // `a` (fed by the sensor) enters the cycle, `b` follows it.
        assert_eq!((at("a"), at("b")), (1, 2), "{layers:?}");
    }

    #[test]
    fn explicit_priority_overrides() {
        let text = CHAIN.replace(
            "name = \"actuator\"\nkind = \"actuator\"",
            "name = \"actuator\"\nkind = \"actuator\"\npriority = -1",
        );
        let g = parse(&text).unwrap();
        assert_eq!(g.node_names(), ["actuator", "sensor", "policy"]);
    }

    #[test]
    fn round_trips_through_toml() {
        for text in [DEFAULT_GRAPH_TOML, CHAIN] {
            let g = parse(text).unwrap();
            let back = GraphSpec::parse(&g.to_toml(), "again").unwrap();
            assert_eq!(g, back);
        }
    }

    const SETPOINT: &str = include_str!("../../../graphs/cartpole-setpoint.toml");

    #[test]
    fn a_python_node_may_read_and_publish_several_topics_and_plays_the_policy() {
        let g = parse(SETPOINT).unwrap();
        let tracker = g.node_id("tracker").unwrap();
        let names = |ts: &[TopicId]| -> Vec<String> {
            ts.iter().map(|t| g.topic(*t).name.clone()).collect()
        };
        assert_eq!(names(&g.node(tracker).subscribes), ["/obs", "/reference"]);
        assert_eq!(names(&g.node(tracker).publishes), ["/action", "/error"]);
        // The chain: the state input makes it the policy; its output toward the actuator
        // is the action; /reference's publisher ranks before it (topological order).
        let chain = g.chain.unwrap();
        assert_eq!(chain.policy, tracker);
        assert_eq!(g.topic(chain.obs).name, "/obs");
        assert_eq!(g.topic(chain.action).name, "/action");
        assert_eq!(
            g.node_names(),
            ["sensor", "reference", "tracker", "actuator"]
        );
        assert_eq!(g.layers(), vec![0, 0, 1, 2]);
        assert!(
            g.to_string().contains("tracker 50 Hz → /action, /error"),
            "{g}"
        );
        // Several topics are written as a list, one as a string, and read back equal.
        let text = g.to_toml();
        assert!(
            text.contains(r#"subscribes = ["/obs", "/reference"]"#),
            "{text}"
        );
        assert!(text.contains(r#"subscribes = "/action""#), "{text}");
        assert_eq!(GraphSpec::parse(&text, "again").unwrap(), g);
    }

    #[test]
    fn an_open_node_driving_the_actuator_is_the_policy_whatever_it_reads() {
        let g = parse(include_str!(
            "../../../graphs/cartpole-position-python.toml"
        ))
        .unwrap();
        let chain = g.chain.unwrap();
        assert_eq!(g.node(chain.policy).name, "controller");
        assert_eq!(g.topic(chain.obs).name, "/meas");
        assert_eq!(g.node(chain.sensor).name, "sensor");
        // One that reads nothing drives the actuator open loop: a valid graph, without
        // the chapter's chain.
        let text = include_str!("../../../graphs/cartpole-position-python.toml")
            .replace("subscribes = \"/meas\"\n", "");
        let text = text.replace(
            "publishes = \"/meas\"",
            "publishes = \"/meas\"\n[[node]]\nname = \"log\"\nkind = \"python\"\nscript = \"l.py\"\nrate_hz = 1\nsubscribes = \"/meas\"",
        );
        let g = parse(&text).unwrap();
        assert_eq!(g.chain, None);
        assert_eq!((g.control_hz(), g.queue_depth()), (None, None));
        assert!(g
            .chain_for("--control-hz", crate::setting::Speech::Flags)
            .unwrap_err()
            .0
            .starts_with("--control-hz speaks of the chapter's chain"));
        // A built-in policy still must read state.
        let e = parse(&CHAIN.replace("type = \"state\"", "type = \"position\"")).unwrap_err();
        assert!(e.reason.contains("type mismatch"), "{e}");
    }

    #[test]
    fn lists_of_topics_are_checked() {
        let reason = |from: &str, to: &str| {
            assert!(SETPOINT.contains(from), "{from}");
            parse(&SETPOINT.replace(from, to)).unwrap_err().reason
        };
        // Only a python node takes several.
        let e = reason(
            "subscribes = \"/action\"",
            "subscribes = [\"/action\", \"/error\"]",
        );
        assert_eq!(
            e,
            "an actuator node subscribes one topic (a python node, or a kind registered with several, may have more)"
        );
        for bad in ["3", "[]", "[\"/obs\", 3]", "{ a = 1 }"] {
            let e = reason(
                "subscribes = [\"/obs\", \"/reference\"]",
                &format!("subscribes = {bad}"),
            );
            assert_eq!(
                e, "subscribes must be a topic name or a list of topic names",
                "{bad}"
            );
        }
        let e = reason(
            "publishes = [\"/action\", \"/error\"]",
            "publishes = [\"/action\", \"/action\"]",
        );
        assert_eq!(e, "publishes names '/action' twice");
        let e = reason(
            "publishes = [\"/action\", \"/error\"]",
            "publishes = [\"/action\", \"/nope\"]",
        );
        assert!(e.starts_with("unknown topic '/nope'"), "{e}");
        // Each topic keeps one publisher.
        let e = reason(
            "publishes = [\"/action\", \"/error\"]",
            "publishes = [\"/action\", \"/reference\"]",
        );
        assert!(
            e.contains("topic '/reference' already has a publisher ('reference')"),
            "{e}"
        );
    }

    /// The registry's list of built-in kinds is the one list: every file of
    /// `graph/nodes/` that defines a kind (`pub fn def() -> KindDef`) is registered under
    /// its file's name, and every kind not registered by a program has its file.
    #[test]
    fn every_built_in_kind_is_registered_under_its_file_s_name() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("graph/nodes");
        let mut files: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| {
                std::fs::read_to_string(p)
                    .unwrap()
                    .contains("pub fn def() -> KindDef")
            })
            .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
            .collect();
        files.sort();
        let mut built_in: Vec<String> = crate::graph::registry::kinds()
            .into_iter()
            .filter(|k| k.code() != crate::graph::kind::Code::Rust)
            .map(|k| k.as_str().to_string())
            .collect();
        built_in.sort();
        assert!(files.len() >= 9, "{files:?}");
        assert_eq!(files, built_in);
        assert_eq!(crate::graph::registry::kind("registered"), None);
    }

    #[test]
    fn a_kinds_parameters_are_checked_and_defaulted() {
        let safety = include_str!("../../../graphs/cartpole-safety.toml");
        let g = parse(safety).unwrap();
        let limit = g.node(g.node_id("safety").unwrap());
        assert_eq!(limit.param("max_force_n"), Some(8.0));
        // In params = { … } too, and a default where the file gives none.
        let g = parse(&safety.replace("max_force_n = 8 ", "params = { max_force_n = 3 }")).unwrap();
        assert_eq!(
            g.node(g.node_id("safety").unwrap()).param("max_force_n"),
            Some(3.0)
        );
        let g = parse(&safety.replace("max_force_n = 8 ", "")).unwrap();
        assert_eq!(
            g.node(g.node_id("safety").unwrap()).param("max_force_n"),
            Some(10.0)
        );
        let e = parse(&safety.replace("max_force_n = 8 ", "max_force_n = 11 ")).unwrap_err();
        assert!(
            e.reason
                .starts_with("max_force_n must be a number in 0..=10 (N), got 11"),
            "{e}"
        );
        // A parameter without a unit says none.
        let camera = include_str!("../../../graphs/cartpole-camera-mujoco.toml");
        let e = parse(&camera.replace("mujoco = 1", "mujoco = true")).unwrap_err();
        assert!(
            e.reason
                .starts_with("params.mujoco must be a number in 0..=1, got true"),
            "{e}"
        );
        let e =
            parse(&safety.replace("max_force_n = 8 ", "params = { max_force = 3 }")).unwrap_err();
        assert_eq!(
            e.reason,
            "a safety node's parameter is max_force_n, not 'max_force'"
        );
        let e = parse(&safety.replace("max_force_n = 8 ", "cutoff_hz = 3 ")).unwrap_err();
        assert_eq!(
            e.reason,
            "a safety node's parameter is max_force_n, not 'cutoff_hz'"
        );
    }

    #[test]
    fn errors_point_at_the_culprit() {
        let e = parse(&CHAIN.replace("kind = \"policy\"", "kind = \"planner\"")).unwrap_err();
        assert_eq!((e.line, e.col), (10, 8), "{e}");
        assert!(e.reason.contains("unknown kind `planner`"), "{e}");
        let e = parse(&CHAIN.replace("depth = 1\n[[topic]]", "depth = 0\n[[topic]]")).unwrap_err();
        assert_eq!(e.line, 22, "{e}");
        assert!(
            e.to_string().starts_with("g.toml:22:9: depth must be"),
            "{e}"
        );
    }

    #[test]
    fn no_two_topic_names_map_to_one_key() {
        for bad in ["/obs/", "//obs", "/a//b", "/", "/a b", "obs"] {
            let text = CHAIN.replace("\"/obs\"", &format!("\"{bad}\""));
            let e = parse(&text).unwrap_err();
            assert!(e.reason.contains("topic name"), "{bad}: {e}");
        }
        for good in ["/obs", "/robot/obs", "/a_1/b2"] {
            let text = CHAIN.replace("\"/obs\"", &format!("\"{good}\""));
            assert!(parse(&text).is_ok(), "{good}");
        }
    }

    #[test]
    fn overrides_follow_the_file_rules() {
        let mut g = GraphSpec::chapter();
        g.set_rate("policy", 5.0).unwrap();
        assert_eq!(g.control_hz(), Some(5.0));
        assert!(g.set_rate("policy", 0.0).is_err());
        assert!(g
            .set_rate("actuator", 40.0)
            .unwrap_err()
            .0
            .contains("50 Hz"));
        assert!(g
            .set_rate("planner", 5.0)
            .unwrap_err()
            .0
            .contains("no node 'planner'"));
        g.set_depth("/obs", 100).unwrap();
        assert_eq!(g.queue_depth(), Some(100));
        assert!(g.set_depth("/obs", 0).is_err());
        assert!(g.set_depth("/nope", 1).is_err());
        // A depth past i64 is said as given, not clamped.
        assert_eq!(
            g.set_depth("/obs", 1 << 63).unwrap_err().0,
            "topic '/obs': depth must be in 1..=1000000, got 9223372036854775808"
        );
        assert_eq!(
            g.set_all_depths(usize::MAX).unwrap_err().0,
            "depth must be in 1..=1000000, got 18446744073709551615"
        );
    }
}
