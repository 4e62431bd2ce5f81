//! The **force** message: a force command on the cart. What a policy publishes and the
//! actuator applies. ROS 2: `std_msgs/msg/Float64` (the chapter's action is one number along
//! the rail; a `geometry_msgs/msg/Wrench` would carry five zeros with it).

use super::{Field, Message, RosCodec, RosMapped};
use crate::ros_types::{float64_type, Float64, RosType};
use crate::time::Nanos;
use serde::{Deserialize, Serialize};

/// A force command on the cart, newtons. The motor's range is ±[`crate::plant::GEAR_N`]
/// (gear 10 on a control in [-1, 1]); the plant clips beyond it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ForceMsg {
    /// Force, N (may be non-finite if a brain misbehaves; the actuator refuses those).
    pub newtons: f64,
}

impl Message for ForceMsg {
    const NAME: &'static str = "force";
    const CLASS: &'static str = "Force";
    const DOC: &'static str = "A force on the cart (the motor's range is ±10 N).";
    const FIELDS: &'static [Field] = &[Field::new("newtons", "N", "force along the rail")];
    fn to_fields(&self) -> Vec<f64> {
        vec![self.newtons]
    }
    fn from_fields(f: &[f64]) -> Self {
        ForceMsg { newtons: f[0] }
    }
    fn ros2() -> Option<RosCodec> {
        Some(RosCodec::of::<Self>())
    }
}

impl RosMapped for ForceMsg {
    type Ros = Float64;
    fn ros_type() -> &'static RosType {
        float64_type()
    }
    fn to_ros(&self, _stamp: Nanos) -> Float64 {
        Float64 { data: self.newtons }
    }
    fn from_ros(f: Float64) -> Result<Self, String> {
        Ok(ForceMsg { newtons: f.data })
    }
}
