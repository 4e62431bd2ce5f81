//! The lab's live sessions: one graph run live under either clock, driven by commands
//! while it runs, with their log and its replay.
//!
//! An engine thread owns the graph and talks to its front end (the terminal lab) over
//! crossbeam channels: [`Control`] in, [`Telemetry`] out. The engine never waits for the
//! front end (telemetry goes into an unbounded channel that the front end drains each
//! frame), and the front end never blocks the graph.
//!
//! Under the virtual clock the engine works one *instant* at a time (every tick due at the
//! same virtual time), paced against the wall clock for display at a chosen speed. Pacing
//! decides only *when* an instant runs, never its order, so it cannot change a result.
//! A rate, depth or brain change is applied between instants and logged with the virtual
//! time of the next instant. The [`SessionLog`] (JSON) therefore replays exactly:
//! [`replay_run`] re-runs a logged run headless and reproduces its metrics byte for byte.
//! Under the real clock changes are applied at once (from each node's next tick); such
//! runs are logged but, being concurrent, cannot be replayed exactly.
//!
//! A file the run's code comes from saved ([`Control::Reload`]) runs the graph again with
//! the new code, judged first and compared with the run before in one line (`reload`), over
//! the span of run time both ran (`compare`). The saved code loads, and is judged, on a
//! thread of its own (`trial`): code whose import or callback never returns is said, never
//! waited for; the run on screen goes on.

mod compare;
mod engine;
mod log;
mod real_run;
mod reload;
mod trial;
mod virtual_run;

pub use engine::{Engine, GraphSource, SessionSettings};
pub use log::{replay_run, LoggedRun, ReplayError, SessionLog};
pub use ratelab_runtime::telemetry::{describe, Control, Speed, Telemetry, SPEEDS, UNBOUNDED};
