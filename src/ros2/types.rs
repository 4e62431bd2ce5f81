//! The ROS 2 message types ratelab's messages are offered as: their descriptions, hashes and
//! CDR layouts live with the messages in the core crate ([`ratelab_core::ros_types`]); this
//! module adds what names them on rmw_zenoh's wire (their [`TypeInfo`]).

use super::rmw_zenoh::entity::{TypeHash, TypeInfo};
pub use ratelab_core::ros_types::*;

/// `t` as rmw_zenoh's tokens and keys name it: its DDS name and RIHS01 hash.
pub fn type_info(t: &RosType) -> TypeInfo {
    TypeInfo::new(&t.dds_name(), TypeHash::new(1, t.hash.0))
}
