//! The **position** message: what a sensor without velocity sensing reports. ROS 2:
//! `sensor_msgs/msg/JointState` without velocities.

use super::{Field, Message, RosCodec, RosMapped};
use crate::ros_types::{joint_state_type, JointState, RosType};
use crate::time::Nanos;
use serde::{Deserialize, Serialize};

/// A position measurement: what a sensor without velocity sensing reports.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PositionMsg {
    /// Cart position, m.
    pub cart_pos_m: f64,
    /// Pole angle from upright, rad, in [-π, π).
    pub pole_angle_rad: f64,
}

impl Message for PositionMsg {
    const NAME: &'static str = "position";
    const CLASS: &'static str = "Position";
    const DOC: &'static str = "A position measurement: no velocities.";
    const FIELDS: &'static [Field] = &[
        Field::new("cart_pos_m", "m", "cart position"),
        Field::new("pole_angle_rad", "rad", "pole angle from upright"),
    ];
    fn to_fields(&self) -> Vec<f64> {
        vec![self.cart_pos_m, self.pole_angle_rad]
    }
    fn from_fields(f: &[f64]) -> Self {
        PositionMsg {
            cart_pos_m: f[0],
            pole_angle_rad: f[1],
        }
    }
    fn ros2() -> Option<RosCodec> {
        Some(RosCodec::of::<Self>())
    }
}

impl RosMapped for PositionMsg {
    type Ros = JointState;
    fn ros_type() -> &'static RosType {
        joint_state_type()
    }
    fn to_ros(&self, stamp: Nanos) -> JointState {
        JointState::of(stamp, vec![self.cart_pos_m, self.pole_angle_rad], vec![])
    }
    /// Both joints' positions, finite (velocities are not read).
    fn from_ros(js: JointState) -> Result<Self, String> {
        let ([x, th], _) = js.joints(false)?;
        Ok(PositionMsg {
            cart_pos_m: x,
            pole_angle_rad: th,
        })
    }
}
