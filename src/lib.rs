//! ratelab: the runtime of robot software — nodes at fixed rates exchanging messages on
//! topics — driving a MuJoCo cartpole, under a deterministic virtual clock or a real one.
//!
//! The semantics (drop rule, tie-break order, zero-order hold, metrics) are ported from the
//! course chapter 2.8 ("Concepts of ROS, without ROS"); time is integer nanoseconds.
//! This crate knows nothing of terminals: the lab (`lab/`) draws it.
//!
//! Layout, one module per idea (every module of the crate, by layer):
//!
//! - **leaves** that many modules share: [`time`] (the `Nanos` newtype), [`ids`] (node and
//!   topic ids and their bounds), [`text`] (text from outside, made safe to show), [`procs`]
//!   (what `/proc` says of a process), [`np_random`] (NumPy-exact seeding), [`input`] and
//!   [`output`] (the rules for files the user names);
//! - **the runtime's parts**: [`clock`], [`rate`], [`qos`] (ROS 2's QoS), [`topic`] (a
//!   subscription's queue and its drop rule), [`msg`] (message types and their registry),
//!   [`publisher`], [`node`], [`plant`] (the MuJoCo cartpole), [`policy`] (brains; +
//!   [`checkpoint`] for trained ones, [`python`] for a learner's code), [`graph`] (the graph
//!   file, [`graph::spec`]; node kinds and their registry), [`executor`] (ROS 2's executors
//!   as rules), [`scheduler`] (the virtual and real clocks that apply them, + [`realtime`]),
//!   [`runlog`], [`metrics`], [`config`];
//! - **runs and their drivers**: [`command`] (changes to a running graph), [`runcore`] (one
//!   graph under the virtual clock, stepped, commanded, captured and restored), [`summary`]
//!   (a run's figures from its graph's state), [`run`] (one run), [`textlog`] (what nodes' code and
//!   ratelab's warnings write, stamped with run time and node), [`session`] (the lab's live runs, their
//!   log and replay), [`sweep`] (grids and the rate cliff), [`exercise`] (the exercises'
//!   bands and checks);
//! - **the world outside**: [`recording`] (rerun `.rrd`), [`ros2`] (ROS 2 on the wire, over
//!   rmw_zenoh's format), [`distributed`] (the graph across processes, over Zenoh).
#![warn(missing_docs)]

pub mod checkpoint;
pub mod clock;
pub mod command;
pub mod config;
pub mod distributed;
pub mod executor;
pub mod exercise;
pub mod graph;
pub mod ids;
pub mod input;
pub mod metrics;
pub mod msg;
pub mod node;
pub mod np_random;
pub mod output;
pub mod plant;
pub mod policy;
pub mod procs;
pub mod publisher;
pub mod python;
pub mod qos;
pub mod rate;
pub mod realtime;
pub mod recording;
pub mod ros2;
pub mod run;
pub mod runcore;
pub mod runlog;
pub mod scheduler;
pub mod session;
pub mod summary;
pub mod sweep;
pub mod text;
pub mod textlog;
pub mod time;
pub mod topic;

pub use config::{ClockKind, RunConfig};
pub use run::{run, RunOptions, RunReport};
pub use time::Nanos;
