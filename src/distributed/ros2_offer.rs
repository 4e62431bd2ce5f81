//! What a process of a launch offers its nodes to ROS 2 with (`ratelab launch --ros2`). The
//! ROS 2 layer (`ratelab_ros2`) stands beside this crate, not below it, so that changing
//! either rebuilds neither the other nor what is built on it alone: it is reached through
//! the one trait here, which the facade implements with it and installs (`ratelab::init()`,
//! which the command line calls first). Without it, `--ros2` is refused in one line
//! ([`NOT_INSTALLED`]).

use crate::DistError;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::{GraphHandles, NodeId};
use ratelab_runtime::scheduler::StopFlag;
use std::sync::OnceLock;

/// What `--ros2` meets in a process when no offer is installed.
pub const NOT_INSTALLED: &str =
    "--ros2 needs ratelab's ROS 2 layer: call ratelab::init() first (the command line does)";

/// Offers a process's nodes to ROS 2.
pub trait Ros2Offer: Send + Sync {
    /// Offer this process's nodes (`mine`, of the graph `handles` holds) to ROS 2 on
    /// `domain`, `/clock` too when it runs the plant's actuator (or the external nodes'
    /// proxies), through a session opened as rmw_zenoh's nodes open theirs.
    ///
    /// # Errors
    /// [`DistError::Usage`]: what the offer refuses (prefixed `--ros2: `);
    /// [`DistError::Zenoh`]: the session.
    fn offer(
        &self,
        domain: u32,
        cfg: &RunConfig,
        handles: &GraphHandles,
        mine: &[NodeId],
        stop: &StopFlag,
    ) -> Result<Box<dyn Offered>, DistError>;
}

/// A process's nodes as offered to ROS 2, until the run's end.
pub trait Offered: Send {
    /// Stop offering and close the session; returns the warnings to print (one line each).
    fn finish(self: Box<Self>) -> Vec<String>;
}

static INSTALLED: OnceLock<&'static dyn Ros2Offer> = OnceLock::new();

/// Install the offer `--ros2` uses, once per process (a second call keeps the first).
pub fn install(offer: &'static dyn Ros2Offer) {
    let _ = INSTALLED.set(offer);
}

/// The offer installed ([`install`]).
///
/// # Errors
/// [`DistError::Usage`] with [`NOT_INSTALLED`] when none is.
pub fn installed() -> Result<&'static dyn Ros2Offer, DistError> {
    INSTALLED
        .get()
        .copied()
        .ok_or_else(|| DistError::Usage(NOT_INSTALLED.to_string()))
}

#[cfg(test)]
mod tests {
    /// The crate's own tests install no offer: `--ros2` is refused in one line, as usage.
    #[test]
    fn without_the_ros2_layer_an_offer_is_refused_as_usage() {
        match super::installed() {
            Err(crate::DistError::Usage(m)) => assert_eq!(m, super::NOT_INSTALLED),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("an offer without the ROS 2 layer"),
        }
    }
}
