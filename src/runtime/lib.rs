//! ratelab's runtime: a graph of nodes at fixed rates, exchanging messages on topics, run
//! against the MuJoCo cartpole under a deterministic virtual clock or a real one. Built on
//! the core crate (`ratelab_core`: time, rates, QoS, topics, messages, node traits, executor
//! rules, metrics), whose modules it uses under their own names.
//!
//! - **the plant and its brains**: [`plant`] (the MuJoCo cartpole), [`policy`] (brains; +
//!   [`checkpoint`] for trained ones; [`graph::interpreter`], where the Python layer plugs
//!   in a learner's code);
//! - **graphs**: [`graph`] (the graph file, [`graph::spec`]; node kinds, their registry and
//!   the built-in nodes; the interpreter their Python nodes and brains are made by), [`config`] (a run's settings and their validation; [`setting`], their
//!   names in each front end's words);
//! - **running them**: [`telemetry`] (a live run's controls and telemetry), [`scheduler`]
//!   (the virtual and real clocks that apply the executors' rules), [`command`] (changes to
//!   a running graph), [`runcore`] (one graph under either clock, stepped, commanded,
//!   captured and restored; every run's driver goes through it), [`summary`] (a run's figures from its graph's state);
//! - **other processes**: [`program`] (how this command line is started again: a launch's
//!   processes, a camera's renderer).
//!
//! The drivers of runs (the headless run, sweeps, the lab's sessions), ROS 2 on the wire,
//! the graph across processes and recordings are crates above this one.
#![warn(missing_docs)]

pub mod checkpoint;
pub mod command;
pub mod config;
pub mod graph;
pub mod plant;
pub mod policy;
pub mod program;
pub mod runcore;
pub mod scheduler;
pub mod setting;
pub mod summary;
pub mod telemetry;

pub use config::{ClockKind, RunConfig};
pub use ratelab_core::Nanos;
