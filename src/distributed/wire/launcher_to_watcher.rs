//! Launcher to watchers (`ratelab top`, `lab --attach`, a recording), on the graph's
//! ended key: the merged summary and how the run ended ([`RunOver`]). JSON.

use ratelab_runtime::scheduler::RunEnd;
use serde::{Deserialize, Serialize};

/// The launcher's word that the run is over (key `ratelab/<graph>/@ended`): the merged
/// summary, as `launch` prints it, for whoever watches (`ratelab lab --attach`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunOver {
    /// The merged metrics.
    pub metrics: ratelab_core::metrics::Metrics,
    /// How the run ended.
    pub end: RunEnd,
}
