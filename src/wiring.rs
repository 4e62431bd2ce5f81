//! The layers that plug into others: what [`crate::init`] installs. The Python layer's
//! interpreter into the runtime, and the ROS 2 layer's offer into the graph across processes
//! (for `launch --ros2`), which stand beside each other: only this crate, above both, joins
//! them.

use ratelab_distributed::ros2_offer::{self, Ros2Offer};
use ratelab_distributed::DistError;
use ratelab_runtime::config::RunConfig;
use ratelab_runtime::graph::{GraphHandles, NodeId};
use ratelab_runtime::scheduler::StopFlag;

/// `launch --ros2`: a process's nodes offered by the ROS 2 layer's bridge.
struct Ros2Launch;

/// A process's nodes offered to ROS 2: the bridge and the session it runs on.
struct Offered {
    bridge: ratelab_ros2::Bridge,
    link: ratelab_ros2::session::Ros2Session,
}

impl Ros2Offer for Ros2Launch {
    fn offer(
        &self,
        domain: u32,
        cfg: &RunConfig,
        handles: &GraphHandles,
        mine: &[NodeId],
        stop: &StopFlag,
    ) -> Result<Box<dyn ros2_offer::Offered>, DistError> {
        use ratelab_ros2::Ros2Error;
        let err = |e: Ros2Error| match e {
            Ros2Error::Usage(m) => DistError::Usage(format!("--ros2: {m}")),
            Ros2Error::Zenoh(m) => DistError::Zenoh(m),
        };
        let env = ratelab_ros2::session::SessionEnv::from_process();
        let link = ratelab_ros2::session::open(&env, stop).map_err(err)?;
        // The external nodes' proxies run here or elsewhere, all in one process
        // (`external::check_placement`), which then publishes /clock at their ticks; without
        // any, the plant's process does.
        let external: Vec<_> = handles
            .external
            .iter()
            .filter(|p| mine.contains(&p.node))
            .cloned()
            .collect();
        let clock = if handles.external.is_empty() {
            mine.contains(&cfg.graph.actuator)
        } else {
            !external.is_empty()
        };
        let offer = ratelab_ros2::bridge::Offer {
            local: Some(mine),
            external: &external,
            clock,
            ..ratelab_ros2::bridge::Offer::whole(handles)
        };
        let opts = ratelab_ros2::Ros2Options {
            domain,
            bag: None,
            force: false,
        };
        let bridge =
            ratelab_ros2::Bridge::start(&link, &offer, &opts, cfg.clock, stop).map_err(err)?;
        Ok(Box::new(Offered { bridge, link }))
    }
}

impl ros2_offer::Offered for Offered {
    fn finish(self: Box<Self>) -> Vec<String> {
        let r = self.bridge.finish();
        let mut warnings: Vec<String> = r.error.iter().map(|e| format!("ROS 2: {e}")).collect();
        warnings.extend(r.external_warnings());
        self.link.close();
        warnings
    }
}

/// Install every layer's plug (idempotent).
pub(crate) fn install() {
    ratelab_python::install();
    ros2_offer::install(&Ros2Launch);
}
