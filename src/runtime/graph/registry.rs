//! The registry of node kinds: from the name a graph file gives as `kind` to the kind's one
//! definition ([`super::kind::KindDef`]). Every kind comes in through [`register_kind`]: the
//! built-in ones (one file each in [`super::nodes`], listed here one line each; `ratelab
//! kinds` prints them) and a Rust program's own, by the same rules; [`register`] is the
//! short way for a kind written as a [`RustNode`], and [`rust_kind`] its definition, to
//! give docs and parameters with units.
//!
//! Every kind's node is a [`RustNode`], the built-in ones included: typed inputs and
//! outputs (copper-rs's `CuTask` is the model), each a
//! [`Message`](ratelab_core::msg::Message) — any registered message type
//! ([`ratelab_core::msg`]: the built-in `StateMsg`, `PositionMsg`, `ForceMsg`, or one of
//! your own, which registering the kind registers too) or [`Held`] of one (every tick's
//! read, stale ones included, with the message's stamps) — or a tuple of two to four of
//! them, or `()` for none ([`Inputs`], [`Outputs`]). A kind written outside ratelab is one
//! too: [`register`] it once, before the graph file is read; from then on
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
//! file gives one: [`ratelab_core::executor`]), carrying the **oldest** origin stamp among the
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
//! program of your own launches it, starting itself as each process: registering its kinds
//! and handing over to the command line as a library (`ratelab_lab::main_with`, in the
//! `lab/` crate) gives it `launch` and every other front end, and
//! `examples/custom_node_processes.rs` is one.

use super::kind::{Code, Kind, KindDef, Params, Plant, Ports};
use super::nodes;
use ratelab_core::msg::MsgType;
use std::sync::{LazyLock, RwLock};

/// The most node kinds one process may have, the built-in ones included
/// ([`ratelab_core::limits::MAX_NODE_KINDS`]).
pub const MAX_KINDS: usize = ratelab_core::limits::MAX_NODE_KINDS;

pub use super::kind::NodeContext;
pub use ratelab_core::ports::{
    AnyPorts, Held, InPort, InputSlot, Inputs, Outputs, RustNode, Stamped,
};

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
    #[error("a process has at most {MAX_KINDS} node kinds, the built-in ones included (ratelab::limits::MAX_NODE_KINDS)")]
    Full,
    /// One of its message types cannot be registered ([`ratelab_core::msg::register`]).
    #[error(transparent)]
    Message(#[from] ratelab_core::msg::MsgRegistryError),
}

/// Every kind: the built-in ones in the chapter's order, then those registered, in the
/// order they were (at most [`MAX_KINDS`] of them: a list is quick enough). The built-in
/// kinds come in by the rules a program's own kinds do ([`register_kind`]).
fn registry() -> &'static RwLock<Vec<Kind>> {
    static REGISTRY: LazyLock<RwLock<Vec<Kind>>> = LazyLock::new(|| {
        let built_in = [
            nodes::sensor::def(),
            nodes::estimator::def(),
            nodes::policy::def(),
            nodes::safety::def(),
            nodes::actuator::def(),
            nodes::python::def(),
            nodes::external::def(),
            nodes::camera::def(),
            nodes::image_estimator::def(),
        ];
        let mut kinds = Vec::new();
        for def in built_in {
            let name = def.name;
            if let Err(e) = admit(&mut kinds, def) {
                panic!("the built-in kind '{name}' breaks the registry's rules: {e}");
            }
        }
        RwLock::new(kinds)
    });
    &REGISTRY
}

/// The kind a graph file's `kind = "<name>"` names, built in or registered.
pub fn kind(name: &str) -> Option<Kind> {
    registry()
        .read()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .copied()
        .find(|k| k.as_str() == name)
}

/// Every kind: the built-in ones in the chapter's order, then those registered, in the
/// order they were.
pub fn kinds() -> Vec<Kind> {
    registry().read().unwrap_or_else(|e| e.into_inner()).clone()
}

/// The registry as a Markdown table, one row per kind in [`kinds`]'s order: its name, what
/// it reads and publishes (message types; `a|b`: either), how it touches the plant, whose
/// code it runs, its parameters (unit, default, range) and its one line of docs. What
/// `ratelab kinds` prints and `docs/graphs.md`'s table of kinds is (a test keeps the two equal).
pub fn kinds_table() -> String {
    let types = |alts: &[ratelab_core::msg::MsgType]| {
        alts.iter()
            .map(|t| format!("`{}`", t.as_str()))
            .collect::<Vec<_>>()
            .join("\\|")
    };
    let ports = |p: &Ports| match p {
        Ports::Fixed { inputs, outputs } => {
            let side = |v: &[&'static [ratelab_core::msg::MsgType]]| match v {
                [] => "—".to_string(),
                v => v
                    .iter()
                    .map(|alts| types(alts))
                    .collect::<Vec<_>>()
                    .join(", "),
            };
            format!("{} → {}", side(inputs), side(outputs))
        }
        Ports::Open {
            max_inputs,
            min_outputs,
            max_outputs,
        } => format!("any: 0–{max_inputs} in → {min_outputs}–{max_outputs} out"),
    };
    let plant = |p: Plant| match p {
        Plant::None => "—",
        Plant::Reads => "reads",
        Plant::Steps => "steps",
    };
    let code = |c: Code| match c {
        Code::BuiltIn => "built in",
        Code::Python => "Python",
        Code::Rust => "Rust (registered)",
        Code::Ros2 => "ROS 2",
    };
    let number = |x: f64| {
        if x.is_infinite() {
            if x > 0.0 { "∞" } else { "−∞" }.to_string()
        } else {
            format!("{x}")
        }
    };
    let params = |p: &Params| match p {
        Params::Free => "any table (the node's code reads it)".to_string(),
        Params::Numbers([]) => "—".to_string(),
        Params::Numbers(defs) => defs
            .iter()
            .map(|d| {
                format!(
                    "`{}`{} (default {}, {}…{})",
                    d.name,
                    if d.unit.is_empty() {
                        String::new()
                    } else {
                        format!(" {}", d.unit)
                    },
                    number(d.default),
                    number(d.min),
                    number(d.max)
                )
            })
            .collect::<Vec<_>>()
            .join("; "),
    };
    let mut out = String::from(
        "| kind | reads → publishes | plant | code | parameters | what it does |\n\
         | --- | --- | --- | --- | --- | --- |\n",
    );
    for k in kinds() {
        let d = k.def();
        out += &format!(
            "| `{}` | {} | {} | {} | {} | {} |\n",
            d.name,
            ports(&d.ports),
            plant(d.plant),
            code(d.code),
            params(&d.params),
            d.doc.replace('|', "\\|")
        );
    }
    out
}

/// Register the node kind `def`: a graph file's `kind = "<def.name>"` then makes a node
/// with `def.make`, and the graph file's rules read the rest (its ports, how it touches the
/// plant, its parameters with units and ranges, its line of docs: `ratelab kinds` prints
/// them). The built-in kinds are registered by this function's rules: each is a `def()` in
/// [`super::nodes`], made of this module's public parts only, and so are its examples
/// (the sensor reads the plant through [`super::kind::RunParts::plant`]; the actuator
/// steps it).
/// Its message types are registered with it ([`ratelab_core::msg::register_type`]).
///
/// # Errors
/// [`RegistryError`]: a bad or taken name, too many kinds, or a message type that cannot
/// be registered.
pub fn register_kind(def: KindDef) -> Result<(), RegistryError> {
    let mut reg = registry().write().unwrap_or_else(|e| e.into_inner());
    admit(&mut reg, def)
}

/// Add `def` to the kinds `reg` holds, by the registry's rules ([`register_kind`]).
fn admit(reg: &mut Vec<Kind>, def: KindDef) -> Result<(), RegistryError> {
    let name = def.name;
    let valid = !name.is_empty()
        && name.len() <= 32
        && name.starts_with(|c: char| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
    if !valid {
        return Err(RegistryError::BadName(name.to_string()));
    }
    if reg.iter().any(|k| k.as_str() == name) {
        return Err(RegistryError::Taken(name.to_string()));
    }
    if reg.len() >= MAX_KINDS {
        return Err(RegistryError::Full);
    }
    // Its message types become usable in graph files with it: all checked first, so that a
    // refusal registers none of them.
    let types: Vec<MsgType> = match &def.ports {
        Ports::Fixed { inputs, outputs } => inputs
            .iter()
            .chain(outputs)
            .flat_map(|alts| alts.iter().copied())
            .collect(),
        Ports::Open { .. } => Vec::new(),
    };
    for t in &types {
        ratelab_core::msg::check_type(*t)?;
    }
    for t in types {
        ratelab_core::msg::register_type(t)?;
    }
    reg.push(Kind(Box::leak(Box::new(def))));
    Ok(())
}

/// The definition of node kind `kind` written in Rust: a [`RustNode`] made by `make` from
/// the node's [`NodeContext`], its typed inputs and outputs its ports, touching no plant,
/// its parameters any table its `make` reads. Set its `doc` and `params` (numbers with
/// units, defaults and ranges, which the graph file's rules then check) before
/// [`register_kind`]; [`register`] registers it as it is.
pub fn rust_kind<N, F>(kind: &str, make: F) -> KindDef
where
    N: RustNode,
    F: Fn(&NodeContext<'_>) -> Result<N, String> + Send + Sync + 'static,
{
    KindDef {
        doc: "a node kind the program registered in Rust",
        ..KindDef::of(kind, move |cx| make(&cx.node))
    }
}

/// Register node kind `kind` written in Rust ([`rust_kind`]: a graph file's `kind =
/// "<kind>"` then makes a node with `make`, given the node's [`NodeContext`]); its message
/// types are registered with it ([`ratelab_core::msg::register`]).
///
/// # Errors
/// [`RegistryError`]: a bad or taken name, too many kinds, or a message type that cannot
/// be registered.
pub fn register<N, F>(kind: &str, make: F) -> Result<(), RegistryError>
where
    N: RustNode,
    F: Fn(&NodeContext<'_>) -> Result<N, String> + Send + Sync + 'static,
{
    register_kind(rust_kind(kind, make))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::kind::{AdapterParts, BuildContext, NodeOf, RunParts};
    use ratelab_core::msg::{AnyTopic, ForceMsg, Message, PositionMsg};
    use ratelab_core::publisher::Outbox;
    use ratelab_core::time::Nanos;
    use std::sync::Arc;

    /// Make a node of kind `kind` as the graph's builder would, around a fresh plant,
    /// named and paced as `cx` says, on `inputs` and `outputs`.
    fn make(
        kind: &str,
        cx: &NodeContext<'_>,
        inputs: &[AnyTopic],
        outputs: &[AnyTopic],
        outbox: &Outbox,
    ) -> Result<NodeOf, String> {
        let k = super::kind(kind).ok_or_else(|| format!("kind '{kind}' is not registered"))?;
        let plant = std::sync::Arc::new(std::sync::Mutex::new(
            crate::plant::CartPole::new().unwrap(),
        ));
        let brain = crate::policy::BrainSlot::new(Box::new(crate::policy::Scripted));
        let log = Arc::new(std::sync::Mutex::new(ratelab_core::runlog::RunLog::new(
            false,
        )));
        let liveliness = Arc::new(ratelab_core::qos::Liveliness::new(None));
        let rate = ratelab_core::rate::Rate::new(1e9 / cx.period.0 as f64).unwrap();
        let mut observers = None;
        (k.def().make)(&mut BuildContext {
            node: NodeContext {
                inputs,
                outputs,
                ..*cx
            },
            run: RunParts {
                plant: &plant,
                brain: &brain,
                log: &log,
                topics: inputs,
                action: None,
                estimate: None,
                observers: &mut observers,
            },
            adapter: AdapterParts {
                python: None,
                rate: &rate,
                liveliness: &liveliness,
                attachment: None,
            },
            outbox,
        })
    }

    /// A context for node `name` at 50 Hz, with no parameters and no topics.
    fn context<'a>(name: &'a str, params: &'a toml::Table) -> NodeContext<'a> {
        NodeContext {
            name,
            id: ratelab_core::ids::NodeId(0),
            period: Nanos(20_000_000),
            seed: 0,
            params,
            inputs: &[],
            outputs: &[],
        }
    }

    type Slots = Vec<&'static [MsgType]>;

    fn shape(kind: &str) -> Option<(Slots, Slots)> {
        match &super::kind(kind)?.def().ports {
            Ports::Fixed { inputs, outputs } => Some((inputs.clone(), outputs.clone())),
            Ports::Open { .. } => None,
        }
    }

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
        let force: &'static [MsgType] = &[ForceMsg::TYPE];
        assert_eq!(shape("echo_unit"), Some((vec![force], vec![force])));
        assert!(kinds().iter().any(|k| k.as_str() == "echo_unit"));
        assert_eq!(kind("echo_unit").unwrap().code(), Code::Rust);
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
        let (f, p): (&'static [MsgType], &'static [MsgType]) =
            (&[ForceMsg::TYPE], &[PositionMsg::TYPE]);
        assert_eq!(shape("mix_bound"), Some((vec![f, p], vec![f, p])));
        let topic = |name: &str, m: MsgType| AnyTopic::new(name, m, 1).unwrap();
        let inputs = [topic("/f", ForceMsg::TYPE), topic("/p", PositionMsg::TYPE)];
        let outputs = [
            topic("/f2", ForceMsg::TYPE),
            topic("/p2", PositionMsg::TYPE),
        ];
        let params = toml::Table::new();
        let cx = context("m", &params);
        // The wrong number of topics is refused (the graph file is checked before).
        assert!(make("mix_bound", &cx, &inputs[..1], &outputs, &Outbox::new()).is_err());
        let mut node = make("mix_bound", &cx, &inputs, &outputs, &Outbox::new()).unwrap();
        let (f, p) = (
            inputs[0].typed::<ForceMsg>().unwrap(),
            inputs[1].typed::<PositionMsg>().unwrap(),
        );
        let (f2, p2) = (
            outputs[0].typed::<ForceMsg>().unwrap(),
            outputs[1].typed::<PositionMsg>().unwrap(),
        );
        let at = |x| PositionMsg {
            cart_pos_m: x,
            pole_angle_rad: 0.0,
        };
        f.publish(ForceMsg { newtons: 1.0 }, Nanos(8), Some(Nanos(7)));
        p.publish(at(0.5), Nanos(3), None); // its own stamp is its origin
        node.0.tick(Nanos(10));
        let (mf, mp) = (f2.read(Nanos(10)).unwrap(), p2.read(Nanos(10)).unwrap());
        assert_eq!((mf.data.newtons, mp.data.cart_pos_m), (1.0, 0.5));
        assert_eq!(
            (mf.origin_stamp, mp.origin_stamp),
            (Some(Nanos(3)), Some(Nanos(3)))
        );
        // Only the force is new: only it is published, still with the older origin.
        f.publish(ForceMsg { newtons: 2.0 }, Nanos(28), Some(Nanos(27)));
        node.0.tick(Nanos(30));
        assert_eq!(f2.read(Nanos(30)).unwrap().origin_stamp, Some(Nanos(3)));
        assert_eq!(p2.stats().published, 1);
        // A newer position: now the force's origin (27) is the oldest.
        p.publish(at(0.7), Nanos(45), None);
        node.0.tick(Nanos(50));
        assert_eq!(p2.read(Nanos(50)).unwrap().origin_stamp, Some(Nanos(27)));
    }

    /// Keeps the newest force it was given, stamp included.
    struct HeldEcho;
    impl RustNode for HeldEcho {
        type Input = Held<ForceMsg>;
        type Output = ForceMsg;
        fn tick(&mut self, _now: Nanos, input: Option<&Stamped<ForceMsg>>) -> Option<ForceMsg> {
            let m = input?;
            Some(ForceMsg {
                newtons: m.data.newtons + m.stamp.0 as f64 + 100.0 * m.seq as f64,
            })
        }
        fn save(&self) -> Option<ratelab_core::node::NodeState> {
            Some(Box::new(()))
        }
        fn load(&mut self, state: &ratelab_core::node::NodeState) -> bool {
            state.is::<()>()
        }
    }

    /// A node of kind `kind` named `name`, reading a force on `/in` and publishing one on
    /// `/out`: the node, and the two topics typed.
    fn force_to_force(
        kind: &str,
        name: &str,
    ) -> (
        NodeOf,
        Arc<ratelab_core::topic::Subscription<ForceMsg>>,
        Arc<ratelab_core::topic::Subscription<ForceMsg>>,
    ) {
        let input = AnyTopic::new("/in", ForceMsg::TYPE, 1).unwrap();
        let output = AnyTopic::new("/out", ForceMsg::TYPE, 1).unwrap();
        let params = toml::Table::new();
        let cx = context(name, &params);
        let (inputs, outputs) = ([input.clone()], [output.clone()]);
        let node = make(kind, &cx, &inputs, &outputs, &Outbox::new()).unwrap();
        (
            node,
            input.typed::<ForceMsg>().unwrap().clone(),
            output.typed::<ForceMsg>().unwrap().clone(),
        )
    }

    /// A held input gives a tick what the topic's read gives, stale reads again, with the
    /// message's stamps; the output carries the held message's origin; a capture takes the
    /// input's position with the node's state.
    #[test]
    fn a_held_input_gives_every_read_with_its_stamps_and_is_captured() {
        register("held_echo", |_: &NodeContext<'_>| Ok(HeldEcho)).unwrap();
        let (mut node, i, o) = force_to_force("held_echo", "h");
        node.0.tick(Nanos(1)); // nothing yet: nothing published
        assert_eq!(o.stats().published, 0);
        i.publish(ForceMsg { newtons: 3.0 }, Nanos(5), Some(Nanos(2)));
        node.0.tick(Nanos(10));
        let saved = node.0.save().expect("the node says how to capture it");
        node.0.tick(Nanos(30)); // a stale read: the same message again
        assert_eq!(o.stats().published, 2);
        let m = o.read(Nanos(30)).unwrap();
        assert_eq!(
            (m.data.newtons, m.stamp, m.origin_stamp),
            (8.0, Nanos(30), Some(Nanos(2)))
        );
        // A newer message moves the input on (its origin is the new message's); the capture
        // is taken back, and a state that is not the node's is refused.
        i.publish(ForceMsg { newtons: 4.0 }, Nanos(35), None);
        node.0.tick(Nanos(40));
        let m = o.read(Nanos(40)).unwrap();
        assert_eq!((m.data.newtons, m.origin_stamp), (139.0, Some(Nanos(35))));
        assert!(node.0.load(&saved));
        assert!(!node
            .0
            .load(&(Box::new(1u8) as ratelab_core::node::NodeState)));
    }

    #[test]
    fn a_bound_node_gets_each_message_once_and_passes_its_origin_on() {
        register("echo_bound", |_: &NodeContext<'_>| Ok(Echo)).unwrap();
        let (mut node, i, o) = force_to_force("echo_bound", "e");
        i.publish(ForceMsg { newtons: 3.0 }, Nanos(5), Some(Nanos(1)));
        node.0.tick(Nanos(10));
        let m = o.read(Nanos(10)).unwrap();
        assert_eq!(
            (m.data.newtons, m.stamp, m.origin_stamp),
            (3.0, Nanos(10), Some(Nanos(1)))
        );
        // Nothing new: Echo publishes nothing.
        node.0.tick(Nanos(30));
        assert_eq!(o.stats().published, 1);
        let params = toml::Table::new();
        assert!(
            make("nobody", &context("e", &params), &[], &[], &Outbox::new())
                .err()
                .unwrap()
                .contains("kind 'nobody' is not registered")
        );
    }
}
