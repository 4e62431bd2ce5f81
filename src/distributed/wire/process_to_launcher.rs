//! Process to launcher, on the process's own key (`@up/<process>`, the only one it may put
//! there): the join, ready, its run's end and its report with the over-the-wire latency
//! of what it received ([`ToLauncher`], [`WireLink`]). JSON.

use ratelab_runtime::scheduler::RunEnd;
use ratelab_runtime::summary::GraphState;
use serde::{Deserialize, Serialize};

/// A process → the launcher (key `ratelab/<graph>/@up`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "msg", rename_all = "snake_case")]
pub enum ToLauncher {
    /// Asks to join, with the SHA-256 of its graph file (hex).
    Join {
        /// Its process name.
        process: String,
        /// SHA-256 of the graph file it was given, hex.
        graph_sha256: String,
        /// Its OS process id.
        pid: u32,
    },
    /// Built, connected, every outbound topic matched: ready to run.
    Ready {
        /// Its process name.
        process: String,
    },
    /// Real clock: its part of the graph ended on its own (a fall, a failed node, the
    /// duration).
    Ended {
        /// Its process name.
        process: String,
        /// How.
        end: RunEnd,
    },
    /// Its state at the end of the run.
    Report {
        /// Its process name.
        process: String,
        /// Its view of the graph.
        state: Box<GraphState>,
        /// The over-the-wire latency of each topic it received from another process.
        wire: Vec<WireLink>,
    },
}

impl ToLauncher {
    /// The sender's process name.
    pub fn process(&self) -> &str {
        match self {
            ToLauncher::Join { process, .. }
            | ToLauncher::Ready { process }
            | ToLauncher::Ended { process, .. }
            | ToLauncher::Report { process, .. } => process,
        }
    }
}

fn is_zero(n: &u64) -> bool {
    *n == 0
}

/// The over-the-wire latency of one topic into one process: from the publisher's send to
/// the subscriber's delivery, on the host's monotonic clock (exact on one host).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireLink {
    /// The topic.
    pub topic: String,
    /// The receiving process.
    pub process: String,
    /// Samples received.
    pub samples: u64,
    /// Latency p50, µs.
    pub p50_us: f64,
    /// Latency p99, µs.
    pub p99_us: f64,
    /// Latency max, µs.
    pub max_us: f64,
    /// Of [`WireLink::samples`], those read in place: they arrived in Zenoh's shared memory
    /// and were read there, not copied out (a message's bytes fields stay a view of the
    /// publisher's buffer). 0 when none did, as for small messages; absent from a report
    /// made before it was counted.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub in_place: u64,
    /// Of [`WireLink::in_place`], those whose frame crossed as its publisher's node drew it:
    /// in the buffer the topic lent the node (`ratelab_core::msg::AnyTopic::loan_pixels`),
    /// never copied between the drawing and the subscriber. 0 when none did; absent from a
    /// report made before it was counted.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub drawn_in_place: u64,
    /// Set by the launcher when the receiving process rejoined mid-run: the run time of its
    /// rejoin, ns. Its figures count from then (the process before it took its own with it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub since_ns: Option<u64>,
}
