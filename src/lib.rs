//! ratelab: the runtime of robot software — nodes at fixed rates exchanging messages on
//! topics — driving a MuJoCo cartpole, under a deterministic virtual clock or a real one.
//!
//! The semantics (drop rule, tie-break order, zero-order hold, metrics) are ported from the
//! course chapter 2.8 ("Concepts of ROS, without ROS"); time is integer nanoseconds.
//! This crate knows nothing of terminals: the lab (`lab/`) draws it.
//!
//! Layout, one module per idea: [`time`], [`clock`], [`topic`], [`rate`], [`node`],
//! [`plant`], [`ids`], [`policy`] (+ brains in [`python`]), [`msg`], [`graph`] (+ its file format, [`graph::spec`]),
//! [`publisher`], [`executor`] (the rules), [`scheduler`] (the clocks that apply them, +
//! [`realtime`]), [`runlog`], [`metrics`], [`config`], [`run`], [`session`],
//! [`distributed`] (the graph across processes, over Zenoh);
//! files the user names are read through [`input`] and written through [`output`]; text from
//! outside is shown through [`text`].
#![warn(missing_docs)]

pub mod checkpoint;
pub mod clock;
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
pub mod runlog;
pub mod scheduler;
pub mod session;
pub mod sweep;
pub mod text;
pub mod time;
pub mod topic;

pub use config::{ClockKind, RunConfig};
pub use run::{run, RunOptions, RunReport};
pub use time::Nanos;
