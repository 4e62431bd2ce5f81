//! Launcher to a process, on the process's control key: the welcome with the run's settings
//! ([`Setup`]), a refusal, the start, the horizon, the run's length in events, the stop and
//! the receipt of the report ([`ToProcess`]). JSON. And under the virtual clock, on the
//! process's relayed key, the other processes' tick reports the launcher hands it
//! ([`encode_relayed`], postcard as they came).

use super::process_to_process::{decode_report_list, Ticked};
use ratelab_core::qos::Fault;
use ratelab_core::time::Nanos;
use ratelab_runtime::config::ClockKind;
use serde::{Deserialize, Serialize};

/// What a process needs to run its part of the graph: the launcher's settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Setup {
    /// The resolved graph (every override applied), as a graph file.
    pub graph_toml: String,
    /// Reset seed.
    pub seed: u64,
    /// Run length, ns.
    pub duration_ns: u64,
    /// Which clock.
    pub clock: ClockKind,
    /// The brain spec (`--policy`).
    pub policy: String,
    /// Faults to inject.
    pub faults: Vec<Fault>,
    /// Each node's first deadline, ns.
    pub phase_offsets_ns: Vec<u64>,
    /// Real clock: the spin margin, ns.
    pub spin_margin_ns: u64,
    /// Real clock: `SCHED_FIFO` priority.
    pub rt_priority: Option<u8>,
    /// `--ros2`: the ROS 2 domain each process offers its own nodes on
    /// (`ratelab::ros2::bridge::Offer::local`); `None`: not offered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2_domain: Option<u32>,
    /// Whether the launch is linked directly ([`crate::launcher::LaunchOptions::star`]):
    /// then a process puts its crossing topics' samples on their own keys and its lockstep
    /// reports for every other process, which each hears directly ([`crate::Keys::topic`],
    /// [`crate::Keys::ticked`]); else on `@via` for the launcher to pass on, and it hears
    /// the others' reports from the launcher ([`crate::Keys::relayed`]).
    #[serde(default)]
    pub direct: bool,
}

impl Setup {
    /// The run these settings describe: the graph parsed from [`Setup::graph_toml`], with
    /// every other setting, validated.
    ///
    /// # Errors
    /// [`crate::DistError::Usage`] naming what is wrong (the bytes came from the network).
    pub fn run_config(&self) -> Result<ratelab_runtime::config::RunConfig, crate::DistError> {
        let spec = ratelab_runtime::graph::spec::GraphSpec::parse(
            &self.graph_toml,
            "the launcher's graph",
        )
        .map_err(|e| crate::DistError::Usage(e.to_string()))?;
        let cfg = ratelab_runtime::config::RunConfig {
            seed: self.seed,
            duration: Nanos(self.duration_ns),
            graph: spec,
            clock: self.clock,
            spin_margin: Nanos(self.spin_margin_ns),
            phase_offsets: self.phase_offsets_ns.iter().copied().map(Nanos).collect(),
            rt_priority: self.rt_priority,
            faults: self.faults.clone(),
        };
        cfg.validate()
            .map_err(|e| crate::DistError::Usage(format!("the launcher's settings: {e}")))?;
        Ok(cfg)
    }
}

/// Launcher → one process (key `ratelab/<graph>/@ctl/<process>`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "msg", rename_all = "snake_case")]
pub enum ToProcess {
    /// Joined: here are the settings.
    Welcome {
        /// The settings.
        setup: Box<Setup>,
        /// The launcher's `CLOCK_MONOTONIC` when it sent this, ns: a real-clock run needs
        /// one host's clock (a process compares it with its own).
        launcher_mono_ns: u64,
    },
    /// Not joined, and why (one line).
    Reject {
        /// Why.
        reason: String,
        /// A process of that name is still running in the graph (as far as the launcher
        /// knows: a process killed a moment ago until its liveliness token is withdrawn). A
        /// process started again at once asks again for a while
        /// ([`crate::process::BUSY_RETRY`]).
        #[serde(default)]
        busy: bool,
    },
    /// Real clock: start; run time zero is at this `CLOCK_MONOTONIC` reading, ns.
    Start {
        /// Run time zero.
        start_mono_ns: u64,
    },
    /// Virtual clock: run every tick due at or before run time `until_ns` (the lockstep's
    /// horizon, [`crate::lockstep`]). The launcher moves it on ahead of the ticks it has
    /// seen done, and stops moving it to end the run early (an interrupt).
    Horizon {
        /// Run time, ns.
        until_ns: u64,
        /// Linked directly: the run time past which the launcher wants the reports a
        /// process keeps for it ([`crate::lockstep::follow_at`]): once the process's run
        /// passes it, it sends what it has kept. `None` in a star (whose processes send the
        /// launcher every report as it is made, no batches); from a launcher of an earlier
        /// ratelab, a batch every [`crate::lockstep::FOLLOWED_BATCH`] reports.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        follow_at_ns: Option<u64>,
    },
    /// Virtual clock, before the stop: the run had `count` events (numbered from 0): take
    /// the report of every one of them before reporting, so that every process has replayed
    /// the whole run's order (its executors' figures are then the run's).
    Events {
        /// The run's events.
        count: u64,
    },
    /// The run ended at run time `at_ns`: once the local copies of the input topics hold
    /// the messages `need` (topic index, seq: the last its publisher sent; virtual clock),
    /// report, and leave once the report is taken ([`ToProcess::ReportTaken`]).
    Stop {
        /// Run time of the end, ns.
        at_ns: u64,
        /// Messages still to arrive before the report.
        #[serde(default)]
        need: Vec<(usize, u64)>,
    },
    /// The launcher has this process's report: it may leave. A process withdraws its
    /// tokens only after this (or after [`crate::process::REPORT_TAKEN_WAIT`]): Zenoh sends
    /// the withdrawal at a higher priority than the report, and a launcher that saw the
    /// process gone first would not wait for its report.
    ReportTaken,
}

/// The most tick reports one message from the launcher to a process carries
/// ([`encode_relayed`]): a process is handed the reports it has not had when its turn comes,
/// or once this many wait for it.
pub const MAX_RELAYED: usize = 1024;

/// Encode tick reports the launcher hands a process (key `ratelab/<graph>/@relayed/<process>`,
/// [`crate::Keys::relayed`]), oldest first, as one message: postcard, the same form as a
/// process's own message of reports. At most [`MAX_RELAYED`] (the caller splits more).
pub fn encode_relayed(reports: &[&Ticked]) -> Vec<u8> {
    postcard::to_allocvec(reports).unwrap_or_default()
}

/// Decode a message of tick reports from the launcher, refusing it whole when it holds none
/// or more than [`MAX_RELAYED`], is over [`MAX_RELAYED`] × [`super::MAX_TICK_BYTES`] bytes or
/// is malformed (exactly, as [`super::decode_reports`]); its text arrives printable. Each
/// report names the process whose event it was.
///
/// # Errors
/// One line.
pub fn decode_relayed(bytes: &[u8]) -> Result<Vec<Ticked>, String> {
    decode_report_list(bytes, MAX_RELAYED)
}
