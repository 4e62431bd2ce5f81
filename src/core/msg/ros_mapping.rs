//! How a message type is offered to ROS 2 (`--ros2`, `ratelab::ros2`): the part of its one
//! definition that names a ROS 2 type and converts to and from it.
//!
//! A type with a mapping implements [`RosMapped`] (a serde struct laid out as the ROS 2
//! message, its [`RosType`] for the RIHS01 hash, and the two conversions) and returns
//! `Some(RosCodec::of::<Self>())` from [`super::Message::ros2`]. CDR (little endian, after
//! the 4-byte encapsulation header) comes from the ROS 2 struct by serde
//! ([`crate::ros_types::cdr`]); what comes in from ROS 2 is bounded and decoded exactly.

use super::{Message, MsgData};
use crate::ros_types::{cdr, from_cdr, RosType};
use crate::time::Nanos;
use serde::de::DeserializeOwned;
use serde::Serialize;

/// A message type offered to ROS 2 as a ROS 2 type.
pub trait RosMapped: Message {
    /// The ROS 2 message, laid out field for field as ROS 2 declares it (serde serializes
    /// it as CDR in that order). Missing fields read from a Python dict default
    /// (`#[serde(default)]`).
    type Ros: Serialize + DeserializeOwned;
    /// The most bytes one message of this type from ROS 2 may have, checked before it is
    /// decoded: 4 KiB unless the type needs more (an image), at most
    /// [`crate::limits::MAX_ROS_MESSAGE_BYTES`]. A message's decoded form can be several
    /// times its bytes (a `JointState` of empty names), so a type keeps it small.
    const MAX_ROS_BYTES: usize = 4096;
    /// The ROS 2 type: name, description, RIHS01 hash.
    fn ros_type() -> &'static RosType;
    /// The ROS 2 message for `self`, published at run time `stamp` (a header's stamp).
    fn to_ros(&self, stamp: Nanos) -> Self::Ros;
    /// `self` from a ROS 2 message (one a ROS 2 node sent: check what must hold).
    ///
    /// # Errors
    /// One line: what in `ros` does not make a message of this type.
    fn from_ros(ros: Self::Ros) -> Result<Self, String>;
}

/// A type's ROS 2 mapping behind function pointers, for the code that handles payloads of
/// any type ([`super::MsgType::ros2`]).
#[derive(Clone, Copy)]
pub struct RosCodec {
    /// The ROS 2 type.
    pub ros_type: fn() -> &'static RosType,
    /// CDR (with its encapsulation header) of a payload published at `stamp`, into `out`
    /// (cleared first); false (and `out` empty) when the payload is not of this type.
    pub encode: fn(&MsgData, Nanos, &mut Vec<u8>) -> bool,
    /// A payload from CDR with its encapsulation header, exactly, within the type's
    /// [`RosMapped::MAX_ROS_BYTES`].
    pub decode: fn(&[u8]) -> Result<MsgData, String>,
    /// The most bytes one message from ROS 2 may have ([`RosMapped::MAX_ROS_BYTES`]).
    pub max_bytes: usize,
}

impl RosCodec {
    /// The codec of `M`'s mapping.
    pub fn of<M: RosMapped>() -> RosCodec {
        RosCodec {
            ros_type: M::ros_type,
            encode: encode::<M>,
            decode: decode::<M>,
            max_bytes: M::MAX_ROS_BYTES.min(crate::limits::MAX_ROS_MESSAGE_BYTES),
        }
    }
}

fn encode<M: RosMapped>(data: &MsgData, stamp: Nanos, out: &mut Vec<u8>) -> bool {
    out.clear();
    match data.get::<M>() {
        Some(m) => {
            cdr(&m.to_ros(stamp), out);
            true
        }
        None => false,
    }
}

fn decode<M: RosMapped>(bytes: &[u8]) -> Result<MsgData, String> {
    Ok(MsgData::new(M::from_ros(from_cdr::<M::Ros>(
        bytes,
        M::MAX_ROS_BYTES,
    )?)?))
}
