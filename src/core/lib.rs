//! ratelab's core: the parts of a robot runtime that every layer above shares, and nothing
//! that talks to the world (no MuJoCo, Zenoh, rerun, Python or neural-network crate: the
//! compiler keeps it so, since none is a dependency).
//!
//! - **leaves**: [`limits`] (every bound on what ratelab is given, in one place),
//!   [`time`] (the `Nanos` newtype), [`ids`] (node and topic ids), [`text`] (text from outside, made safe to show), [`np_random`] (NumPy-exact
//!   seeding), [`procs`] (what `/proc` says of a process), [`input`] and [`output`] (the
//!   rules for files the user names), [`textlog`] (what nodes' code and ratelab's warnings
//!   write, stamped with run time and node);
//! - **the runtime's parts**: [`clock`] (virtual and monotonic time, [`clock::ClockKind`]),
//!   [`rate`] (rates, periods and sleeping to a deadline), [`realtime`] (thread priorities),
//!   [`qos`] (ROS 2's QoS), [`topic`] (a subscription's queue and its drop rule), [`msg`]
//!   (message types and their registry, with [`ros_types`], their ROS 2 side, and [`pixels`],
//!   an image's shared bytes, beneath both),
//!   [`publisher`], [`node`] (the node traits) and [`ports`] (a Rust node's typed inputs and
//!   outputs), [`executor`] (ROS 2's executors as rules), [`plant`] (the cartpole's facts),
//!   [`runlog`] (what a run logs), [`estimate`] (an estimator against the truth) and [`metrics`].
//!
//! A program depends on `ratelab`, which re-exports every module here under the same name.
#![warn(missing_docs)]

pub mod clock;
pub mod estimate;
pub mod executor;
pub mod ids;
pub mod input;
pub mod limits;
pub mod metrics;
pub mod msg;
pub mod node;
pub mod np_random;
pub mod output;
pub mod pixels;
pub mod plant;
pub mod ports;
pub mod procs;
pub mod publisher;
pub mod qos;
pub mod rate;
pub mod realtime;
pub mod ros_types;
pub mod runlog;
pub mod text;
pub mod textlog;
pub mod time;
pub mod topic;

pub use time::Nanos;
