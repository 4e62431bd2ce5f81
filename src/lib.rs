//! ratelab: the runtime of robot software — nodes at fixed rates exchanging messages on
//! topics — driving a MuJoCo cartpole, under a deterministic virtual clock or a real one.
//!
//! The semantics (drop rule, tie-break order, zero-order hold, metrics) are ported from the
//! course chapter 2.8 ("Concepts of ROS, without ROS"); time is integer nanoseconds. No
//! crate of the library knows terminals: the lab (`lab/`) draws it.
//!
//! This crate is the one a Rust program depends on: it re-exports every layer's modules
//! under one name (the exercises, `ratelab-exercises` in `src/exercises/`, are the lab's,
//! not the facade's). The layers are crates of their own, each
//! depending only on those below it (the workspace's `Cargo.toml` lists them):
//!
//! - **core** (`ratelab_core`, `src/core/`) — leaves that many modules share: [`time`] (the
//!   `Nanos` newtype), [`limits`] (every bound on input, in one place), [`ids`] (node and topic ids), [`text`] (text from
//!   outside, made safe to show), [`textlog`] (what nodes' code and ratelab's warnings write,
//!   stamped with run time and node), [`procs`] (what `/proc` says of a process),
//!   [`np_random`] (NumPy-exact seeding), [`input`] and [`output`] (the rules for files the
//!   user names); and the runtime's parts: [`clock`], [`rate`], [`realtime`], [`qos`]
//!   (ROS 2's QoS), [`topic`] (a subscription's queue and its drop rule), [`msg`] (message
//!   types and their registry, with [`ros_types`], their ROS 2 side, and [`pixels`], an
//!   image's shared bytes), [`publisher`],
//!   [`node`] and [`ports`] (the node trait, [`ports::RustNode`]), [`executor`] (ROS 2's executors as rules),
//!   [`runlog`], [`estimate`] (an estimator against the truth), [`metrics`];
//! - **runtime** (`ratelab_runtime`, `src/runtime/`): [`plant`] (the MuJoCo cartpole),
//!   [`policy`] (brains; + [`checkpoint`] for trained ones; [`graph::interpreter`],
//!   where the Python layer plugs in), [`graph`] (the graph file, [`graph::spec`]; node kinds and
//!   their registry), [`config`], [`scheduler`] (the virtual and real clocks), [`command`]
//!   (changes to a running graph), [`runcore`] (one graph under either clock, stepped,
//!   commanded, captured and restored), [`summary`] (a run's figures from its graph's
//!   state), [`telemetry`] (a live run's controls and telemetry);
//! - **python** (`ratelab_python`, `src/python/`): [`python`] (a learner's Python nodes
//!   and brains in the embedded interpreter; [`init`] installs it for the runtime);
//! - **ros2** (`ratelab_ros2`, `src/ros2/`): [`ros2`] (ROS 2 on the wire, over rmw_zenoh's
//!   format; ROS 2 nodes as a graph's external nodes; bags);
//! - **recording** (`ratelab_recording`, `src/recording/`): [`recording`] (rerun `.rrd`);
//! - **distributed** (`ratelab_distributed`, `src/distributed/`): [`distributed`] (the graph
//!   across processes, over Zenoh);
//! - **drivers** (`ratelab_drivers`, `src/drivers/`): [`run_spec`] (a run as data, every
//!   front end's settings under one set of rules; [`setting`], their names), [`start`] (a
//!   run started from them, as every front end starts one), [`outputs`]
//!   (what a run writes and offers; [`trace_csv`], its trace as it goes), [`observer`]
//!   (what watches a run as it goes: a recording, a progress bar), [`held_run`] (a
//!   run's results in memory, for a host program), and the run core's drivers —
//!   [`run`](mod@run) (one headless run), [`sweep`] (grids and the rate cliff;
//!   [`sweep_spec`], a sweep or cliff search as data, under the same rules for every front
//!   end), [`session`] (the lab's live sessions, their log and replay).
#![warn(missing_docs)]

mod wiring;

/// Connect the layers that plug into others: install the Python layer's interpreter
/// ([`python::install`]), which runs Python nodes and brains for the runtime
/// ([`graph::interpreter`]), and the ROS 2 layer's offer of a process's nodes for the graph across
/// processes ([`distributed::ros2_offer`], `launch --ros2`). The command line calls it
/// first; a program that runs Python nodes or brains, or launches with `--ros2`, through the
/// library calls it once before (else that is refused, in one line saying so). Idempotent
/// and cheap.
pub fn init() {
    wiring::install();
}

// The core crate's and the runtime crate's modules, under their own names (`ratelab::time`,
// `ratelab::graph`, …).
pub use ratelab_core::{
    clock, estimate, executor, ids, input, limits, metrics, msg, node, np_random, output, pixels,
    ports, procs, publisher, qos, rate, realtime, ros_types, runlog, text, textlog, time, topic,
    Nanos,
};
pub use ratelab_distributed as distributed;
pub use ratelab_drivers::{
    held_run, observer, outputs, run, run_spec, session, start, sweep, sweep_spec, trace_csv,
};
pub use ratelab_python as python;
pub use ratelab_recording as recording;
pub use ratelab_ros2 as ros2;
pub use ratelab_runtime::{
    checkpoint, command, config, graph, plant, policy, runcore, scheduler, setting, summary,
    telemetry,
};
pub use ratelab_runtime::{ClockKind, RunConfig};
// `ratelab::run` is the module and, as before the layers were crates, its function.
pub use ratelab_drivers::run::{run, RunOptions, RunReport};
