//! ROS 2 on the wire: a running graph offered as a ROS 2 graph, in rmw_zenoh's format, so
//! that ROS 2's own tools (`ros2 topic list / echo / hz`, `ros2 node list`, rqt_graph) on a
//! machine with `RMW_IMPLEMENTATION=rmw_zenoh_cpp` see it, and ROS 2 nodes with
//! `use_sim_time` follow its clock on `/clock`.
//!
//! The parts, one idea each:
//! - [`names`]: ROS 2's rules for domains, topic and node names (pure, checked first);
//! - [`types`]: the ROS 2 types ratelab's message types are offered as (each type's own
//!   definition names its mapping, [`ratelab_core::msg::RosMapped`]), their RIHS01 hashes and CDR;
//! - [`session`]: the Zenoh session rmw_zenoh's nodes open by default (peer, a router at
//!   `tcp/localhost:7447`, `ZENOH_ROUTER_CHECK_ATTEMPTS`, `ZENOH_CONFIG_OVERRIDE`), or an
//!   embedded router when none answers;
//! - [`bag`]: `--bag DIR`, what is offered as a rosbag2 bag (MCAP storage); [`bag_reader`]:
//!   any such bag read back (`ratelab ros2 bag info|echo`), a type ratelab has no
//!   description of decoded by the `ros2msg` schema the bag carries ([`msg_schema`], parsed
//!   by rerun's `re_ros_msg`);
//! - [`bridge`]: the liveliness tokens (NN per node, MP/MS per publisher and subscription,
//!   with the QoS), a publisher per topic on `<domain>/<topic>/<dds type>/<RIHS01>` with
//!   rmw_zenoh's 33-byte attachment, and `/clock`;
//! - [`external`]: nodes of `kind = "external"`, which a ROS 2 node fills: waiting for
//!   their tokens, checking their types, hearing what they publish, and the lockstep's
//!   time contract under the virtual clock;
//! - [`rmw_zenoh`]: rmw_zenoh's key expressions, liveliness tokens and QoS strings,
//!   written and read (ratelab's own, from rmw_zenoh's `docs/design.md`), every token read
//!   from the network bounded and checked;
//! - [`wire`]: declaring an endpoint (key, token, GID), rmw_zenoh's attachment, a put
//!   stamped by its publisher's session;
//! - [`node_api`]: what every ROS 2 node declares besides its topics — `/rosout` (the log
//!   pane's lines), `/parameter_events` and the parameter services, answering from the graph
//!   file's parameters ([`parameters`]) in `rcl_interfaces`' types ([`rcl_interfaces`]), and
//!   `~/get_type_description` ([`type_description`], which `echo` also asks of other nodes);
//! - [`inspect`] and [`echo`]: `ratelab ros2`, any rmw_zenoh graph read from the other side
//!   as ros2cli reads it (nodes, topics, QoS, messages as YAML, rates: [`figures`]);
//!   [`offered`]: a graph as ROS 2 sees it when offered (the lab's panel); [`param_cli`]:
//!   `ratelab ros2 param list|get`; [`subscription`]: how `echo`, `hz` and `bw` subscribe
//!   (ros2cli's QoS choice, rmw_zenoh_cpp's subscription for it: a latched topic's stored
//!   messages at once);
//! - [`yaml_depth`]: how deeply YAML read from outside (a bag's `metadata.yaml`, a
//!   parameter's value) nests, bounded before a parser sees it.
//!
//! The format is rmw_zenoh's `docs/design.md`; its keys, tokens and QoS strings are
//! ratelab's own ([`rmw_zenoh`]), its hashes come from ZettaScale's `hiroz-schema`, its CDR
//! from `hiroz-cdr`.
//! The tests check all of it against independent implementations (`eclipse-zenoh`,
//! `rosbags`); no ROS 2 installation was available to check against (docs/ros2.md).
//!
//! What is offered is a view: ratelab's own topics, clocks and drop rules are unchanged,
//! and a run with `--ros2` gives the same results as one without.
#![warn(missing_docs)]

pub mod bag;
pub mod bag_reader;
pub mod bridge;
pub mod echo;
pub mod external;
pub mod figures;
pub mod inspect;
pub mod msg_schema;
pub mod names;
pub mod node_api;
pub mod offered;
pub mod param_cli;
pub mod parameters;
pub mod rcl_interfaces;
pub mod rmw_zenoh;
pub mod session;
pub mod subscription;
pub mod type_description;
pub mod types;
pub mod wire;
pub mod yaml_depth;

pub use bridge::{Bridge, BridgeReport};

/// How a graph is offered to ROS 2.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ros2Options {
    /// The ROS 2 domain, 0–[`names::MAX_DOMAIN_ID`] (`ROS_DOMAIN_ID`): the first part of
    /// every key and token.
    pub domain: u32,
    /// Also write what is offered as a rosbag2 bag (MCAP) in this folder ([`bag`]).
    pub bag: Option<std::path::PathBuf>,
    /// Replace a bag already in that folder.
    pub force: bool,
}

/// Why a graph cannot be offered to ROS 2.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// Bad input (a name, a domain, a setting, a second `/clock` publisher): exit 2.
    #[error("{0}")]
    Usage(String),
    /// Zenoh failed.
    #[error("Zenoh: {0}")]
    Zenoh(String),
}

/// A Zenoh error as [`Ros2Error::Zenoh`], in one line.
pub(crate) fn zerr(e: impl std::fmt::Display) -> Ros2Error {
    Ros2Error::Zenoh(e.to_string().lines().next().unwrap_or_default().to_string())
}

/// The ROS 2 type message type `msg` is offered as.
///
/// # Panics
/// When `msg` has none: [`crate::bridge::check_graph`] refuses such a graph first.
pub fn ros_type_of(msg: ratelab_core::msg::MsgType) -> &'static types::RosType {
    (msg.ros2()
        .expect("a graph offered to ROS 2 has only mapped types")
        .ros_type)()
}

/// `f()`, with a panic inside it (in a dependency reading outside bytes: a bag's records,
/// a bag's `ros2msg` schema) caught and given back as its message, printed by nobody: one
/// line is said of it by the caller ([`bag_reader`], [`msg_schema`]).
///
/// The process's panic hook is silenced meanwhile: by one thread at a time (so that two
/// threads cannot leave it silenced for good), once for calls inside calls (a bag's walk
/// decoding by a schema), which run within the outer call's silence.
pub(crate) fn catching_panics<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    use std::cell::Cell;
    use std::panic::{catch_unwind, set_hook, take_hook, AssertUnwindSafe};
    thread_local!(static SILENCED: Cell<bool> = const { Cell::new(false) });
    static HOOK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let message = |p: Box<dyn std::any::Any + Send>| {
        p.downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| p.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "a panic".into())
    };
    if SILENCED.with(Cell::get) {
        return catch_unwind(AssertUnwindSafe(f)).map_err(message);
    }
    let _one = HOOK.lock().unwrap_or_else(|e| e.into_inner());
    SILENCED.with(|s| s.set(true));
    let hook = take_hook();
    set_hook(Box::new(|_| {}));
    let r = catch_unwind(AssertUnwindSafe(f));
    set_hook(hook);
    SILENCED.with(|s| s.set(false));
    r.map_err(message)
}
