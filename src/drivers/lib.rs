//! The drivers of the run core ([`ratelab_runtime::runcore`]), one per front end: [`run`]
//! (one headless run, end to end, under either clock), [`sweep`] (grids of runs and the
//! rate cliff) and [`session`] (the lab's live sessions: the graph driven by commands
//! while it runs, their log and its replay). The graph across processes drives the same
//! core from `ratelab-distributed`.

// The layers below, under their own names (`crate::graph`, `crate::time`, …).
use ratelab_core::{
    executor, input, limits, metrics, output, plant, qos, realtime, runlog, textlog, time,
};
use ratelab_recording as recording;
use ratelab_ros2 as ros2;
use ratelab_runtime::{
    checkpoint, command, config, graph, policy, runcore, scheduler, summary, telemetry,
};

pub mod run;
pub mod session;
pub mod sweep;
