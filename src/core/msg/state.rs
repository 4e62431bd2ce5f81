//! The **state** message: the full state as the chapter's observation, `float32[5]`. What a
//! full-state sensor and an estimator publish and a policy reads. ROS 2:
//! `sensor_msgs/msg/JointState` (joints `slider`, `hinge`; the pole's position is
//! `atan2(sin θ, cos θ)`).

use super::{Field, Message, RosCodec, RosMapped};
use crate::plant::Observation;
use crate::ros_types::{joint_state_type, JointState, RosType};
use crate::time::Nanos;

/// The full state, as the chapter's observation: `float32[5]` = cart position m, cart
/// velocity m/s, cos θ, sin θ, pole angular velocity rad/s.
pub type StateMsg = Observation;

impl Message for StateMsg {
    const NAME: &'static str = "state";
    const CLASS: &'static str = "State";
    const DOC: &'static str = "The full state, the chapter's observation (float32 on the topic).";
    const FIELDS: &'static [Field] = &[
        Field::new("cart_pos_m", "m", "cart position"),
        Field::new("cart_vel_m_s", "m/s", "cart velocity"),
        Field::new("cos_theta", "1", "cosine of the pole angle"),
        Field::new("sin_theta", "1", "sine of the pole angle"),
        Field::new("pole_angvel_rad_s", "rad/s", "pole angular velocity"),
    ];
    fn to_fields(&self) -> Vec<f64> {
        self.map(f64::from).to_vec()
    }
    fn from_fields(f: &[f64]) -> Self {
        std::array::from_fn(|i| f.get(i).copied().unwrap_or(0.0) as f32)
    }
    fn ros2() -> Option<RosCodec> {
        Some(RosCodec::of::<Self>())
    }
}

impl RosMapped for StateMsg {
    type Ros = JointState;
    fn ros_type() -> &'static RosType {
        joint_state_type()
    }
    fn to_ros(&self, stamp: Nanos) -> JointState {
        let o = self.map(f64::from);
        JointState::of(stamp, vec![o[0], o[3].atan2(o[2])], vec![o[1], o[4]])
    }
    /// Both joints' positions and velocities (named `slider`, `hinge` in that order, or
    /// unnamed), finite; the observation is `[x, ẋ, cos θ, sin θ, θ̇]` as float32. The
    /// header is not read: the proxy stamps what it delivers.
    fn from_ros(js: JointState) -> Result<Self, String> {
        let ([x, th], [xd, thd]) = js.joints(true)?;
        Ok([x, xd, th.cos(), th.sin(), thd].map(|v| v as f32))
    }
}
