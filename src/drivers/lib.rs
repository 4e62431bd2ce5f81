//! A run as data, [`run_spec`] (every front end's settings and their rules, in one place),
//! and [`start`] (a run started from them, the same way for every front end: checked once,
//! its outputs opened and attached), its [`outputs`] (files, recording, ROS 2;
//! [`trace_csv`], the trace written as it goes), [`observer`] (what watches a run as it
//! goes: one trait for a recording, the trace's writer, a progress bar), [`held_run`] (a
//! run's results returned in memory, for a host program),
//! and the drivers of the run core ([`ratelab_runtime::runcore`]), one per front end: [`run`]
//! (one headless run, end to end, under either clock), [`sweep`] (grids of runs and the
//! rate cliff; [`sweep_spec`], a sweep or cliff search as data, checked by one set of rules
//! for every front end) and [`session`] (the lab's live sessions: the graph driven by commands
//! while it runs, their log and its replay). The graph across processes drives the same
//! core from `ratelab-distributed`.
#![warn(missing_docs)]

pub mod held_run;
pub mod observer;
pub mod outputs;
pub mod run;
pub mod run_spec;
pub mod session;
pub mod start;
pub mod sweep;
pub mod sweep_spec;
pub mod trace_csv;
