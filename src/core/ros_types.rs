//! The ROS 2 message types ratelab's messages are offered as — their descriptions (for the
//! RIHS01 hash in every key and token), their serde layouts (CDR) — and `/clock`. Which
//! ratelab type maps to which, and how, is part of each message type's one definition
//! ([`crate::msg::RosMapped`], in `src/core/msg/<type>.rs`); this module holds only ROS 2's side.
//! The built-in types map so:
//!
//! | ratelab  | ROS 2 type                   | fields (units)                                              |
//! |----------|------------------------------|-------------------------------------------------------------|
//! | state    | `sensor_msgs/msg/JointState` | `name = [slider, hinge]`; `position` = [cart m, pole rad]; `velocity` = [cart m/s, pole rad/s]; `effort` empty |
//! | position | `sensor_msgs/msg/JointState` | `name = [slider, hinge]`; `position` = [cart m, pole rad]; `velocity`, `effort` empty |
//! | force    | `std_msgs/msg/Float64`       | `data` = force on the cart, N                                 |
//! | image    | `sensor_msgs/msg/Image`      | `height`, `width` px; `encoding`; `is_bigendian` = 0; `step` B; `data` = the pixels |
//! | (clock)  | `rosgraph_msgs/msg/Clock`    | `clock` = run time (`builtin_interfaces/msg/Time`)            |
//!
//! The joint names are the MuJoCo model's (`src/assets/cartpole.xml`). The state's pole
//! angle is `atan2(sin θ, cos θ)` of the chapter's observation (which carries cos θ and
//! sin θ as float32); its header's stamp is the message's publish stamp in run time, the
//! time `/clock` gives ROS 2 nodes with `use_sim_time`. The force is a plain `Float64`
//! rather than `geometry_msgs/msg/Wrench`: the chapter's action is one number along the
//! rail, and a `Wrench` would carry five zeros with it.
//! An image's pixels are written and read as one run of bytes (a `uint8` sequence is its
//! length and its bytes in CDR); one from ROS 2 must be whole (`step × height` bytes) and
//! little-endian (`is_bigendian` 0: ratelab's image has no byte order of its own).
//!
//! Encoding: CDR little endian after the 4-byte encapsulation header `00 01 00 00`
//! (`CDR_LE`), as rmw_zenoh sends, by `hiroz-cdr`. The type hashes come from
//! `hiroz-schema`'s RIHS01 (the tests check them against `rosbags`' `hash_rihs01`).

use crate::limits::{self, MAX_ROS_MESSAGE_BYTES};
use crate::pixels::ImageData;
use crate::time::Nanos;
use hiroz_schema::{
    FieldDescription, FieldTypeDescription, TypeDescription, TypeDescriptionMsg, TypeHash, TypeId,
};
use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

/// The joint names of the state's `JointState`, in order: the cart's slide joint and the
/// pole's hinge (the MuJoCo model's names).
pub const JOINT_NAMES: [&str; 2] = ["slider", "hinge"];

/// The CDR encapsulation header for little-endian plain CDR (`CDR_LE`).
pub const CDR_LE_HEADER: [u8; 4] = [0, 1, 0, 0];

/// A ROS 2 message type: its name, description and RIHS01 hash.
#[derive(Debug)]
pub struct RosType {
    /// The fully qualified name, `package/msg/Name` (`sensor_msgs/msg/JointState`).
    pub name: &'static str,
    /// The type and every type it refers to, as `type_description_interfaces` has them.
    pub description: TypeDescriptionMsg,
    /// Its RIHS01 hash (SHA-256 of the description's canonical JSON).
    pub hash: TypeHash,
}

impl RosType {
    fn new(
        name: &'static str,
        fields: Vec<FieldDescription>,
        mut referenced: Vec<TypeDescription>,
    ) -> RosType {
        // RIHS01 hashes the referenced types sorted by name.
        referenced.sort_by(|a, b| a.type_name.cmp(&b.type_name));
        let description = TypeDescriptionMsg {
            type_description: describe(name, fields),
            referenced_type_descriptions: referenced,
        };
        let hash = hiroz_schema::calculate_hash(&description);
        RosType {
            name,
            description,
            hash,
        }
    }

    /// The DDS name rmw_zenoh puts in keys and tokens (`sensor_msgs::msg::dds_::JointState_`).
    pub fn dds_name(&self) -> String {
        hiroz_schema::dds_from_canonical(self.name).unwrap_or_else(|| self.name.to_string())
    }
}

const JOINT_STATE: &str = "sensor_msgs/msg/JointState";
const FLOAT64: &str = "std_msgs/msg/Float64";
const CLOCK: &str = "rosgraph_msgs/msg/Clock";
const TIME: &str = "builtin_interfaces/msg/Time";
const HEADER: &str = "std_msgs/msg/Header";
const IMAGE: &str = "sensor_msgs/msg/Image";

fn field(name: &str, field_type: FieldTypeDescription) -> FieldDescription {
    FieldDescription {
        name: name.to_string(),
        field_type,
        default_value: String::new(),
    }
}

fn describe(type_name: &str, fields: Vec<FieldDescription>) -> TypeDescription {
    TypeDescription {
        type_name: type_name.to_string(),
        fields,
    }
}

fn time() -> TypeDescription {
    describe(
        TIME,
        vec![
            field("sec", FieldTypeDescription::primitive(TypeId::INT32)),
            field("nanosec", FieldTypeDescription::primitive(TypeId::UINT32)),
        ],
    )
}

fn header() -> TypeDescription {
    describe(
        HEADER,
        vec![
            field(
                "stamp",
                FieldTypeDescription::nested(TypeId::NESTED_TYPE, TIME),
            ),
            field("frame_id", FieldTypeDescription::primitive(TypeId::STRING)),
        ],
    )
}

/// `sensor_msgs/msg/JointState`: the type the state and position messages are offered as.
pub fn joint_state_type() -> &'static RosType {
    static JOINT: OnceLock<RosType> = OnceLock::new();
    JOINT.get_or_init(|| {
        let seq = |t: u8| FieldTypeDescription::primitive(t + TypeId::UNBOUNDED_SEQUENCE_OFFSET);
        RosType::new(
            JOINT_STATE,
            vec![
                field(
                    "header",
                    FieldTypeDescription::nested(TypeId::NESTED_TYPE, HEADER),
                ),
                field("name", seq(TypeId::STRING)),
                field("position", seq(TypeId::FLOAT64)),
                field("velocity", seq(TypeId::FLOAT64)),
                field("effort", seq(TypeId::FLOAT64)),
            ],
            vec![header(), time()],
        )
    })
}

/// `sensor_msgs/msg/Image`: the type the image message is offered as.
pub fn image_type() -> &'static RosType {
    static IMG: OnceLock<RosType> = OnceLock::new();
    IMG.get_or_init(|| {
        let one = FieldTypeDescription::primitive;
        RosType::new(
            IMAGE,
            vec![
                field(
                    "header",
                    FieldTypeDescription::nested(TypeId::NESTED_TYPE, HEADER),
                ),
                field("height", one(TypeId::UINT32)),
                field("width", one(TypeId::UINT32)),
                field("encoding", one(TypeId::STRING)),
                field("is_bigendian", one(TypeId::UINT8)),
                field("step", one(TypeId::UINT32)),
                field(
                    "data",
                    one(TypeId::UINT8 + TypeId::UNBOUNDED_SEQUENCE_OFFSET),
                ),
            ],
            vec![header(), time()],
        )
    })
}

/// `std_msgs/msg/Float64`: the type the force message is offered as.
pub fn float64_type() -> &'static RosType {
    static F64: OnceLock<RosType> = OnceLock::new();
    F64.get_or_init(|| {
        RosType::new(
            FLOAT64,
            vec![field(
                "data",
                FieldTypeDescription::primitive(TypeId::FLOAT64),
            )],
            vec![],
        )
    })
}

/// `rosgraph_msgs/msg/Clock`, the type of `/clock`.
pub fn clock_type() -> &'static RosType {
    static C: OnceLock<RosType> = OnceLock::new();
    C.get_or_init(|| {
        RosType::new(
            CLOCK,
            vec![field(
                "clock",
                FieldTypeDescription::nested(TypeId::NESTED_TYPE, TIME),
            )],
            vec![time()],
        )
    })
}

/// `builtin_interfaces/msg/Time`: whole seconds and nanoseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds (run time: from 0 at the run's start).
    pub sec: i32,
    /// Nanoseconds within the second, < 10⁹.
    pub nanosec: u32,
}

impl Time {
    /// Run time `t` as a ROS 2 time (saturating at `i32::MAX` s, 68 years).
    pub fn of(t: Nanos) -> Time {
        Time {
            sec: i32::try_from(t.0 / 1_000_000_000).unwrap_or(i32::MAX),
            nanosec: (t.0 % 1_000_000_000) as u32,
        }
    }
}

/// `std_msgs/msg/Header`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// The publish stamp, run time.
    pub stamp: Time,
    /// Empty: the cartpole has one frame, the world.
    pub frame_id: String,
}

/// `sensor_msgs/msg/JointState`. A field missing from a dict (Python's `from_ros`) reads
/// as empty.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct JointState {
    /// The stamp.
    pub header: Header,
    /// [`JOINT_NAMES`].
    pub name: Vec<String>,
    /// Cart position m, pole angle rad.
    pub position: Vec<f64>,
    /// Cart velocity m/s, pole angular velocity rad/s (empty for a position message).
    pub velocity: Vec<f64>,
    /// Empty.
    pub effort: Vec<f64>,
}

impl JointState {
    /// The cartpole's joints ([`JOINT_NAMES`]) at run time `stamp`: positions (cart m, pole
    /// rad) and velocities (cart m/s, pole rad/s; empty for none).
    pub fn of(stamp: Nanos, position: Vec<f64>, velocity: Vec<f64>) -> JointState {
        JointState {
            header: Header {
                stamp: Time::of(stamp),
                frame_id: String::new(),
            },
            name: JOINT_NAMES.iter().map(|s| s.to_string()).collect(),
            position,
            velocity,
            effort: vec![],
        }
    }

    /// Both joints' positions and, with `velocities`, velocities (`[0, 0]` without), as a
    /// ROS 2 node sent them: named [`JOINT_NAMES`] in that order, or unnamed, and finite.
    ///
    /// # Errors
    /// One line: other joint names, a joint missing, or a non-finite value.
    pub fn joints(&self, velocities: bool) -> Result<([f64; 2], [f64; 2]), String> {
        let named = self.name.is_empty() || self.name.iter().map(String::as_str).eq(JOINT_NAMES);
        if !named {
            return Err(format!(
                "JointState names {:?}, not {JOINT_NAMES:?}",
                self.name
            ));
        }
        let two = |v: &[f64], what: &str| -> Result<[f64; 2], String> {
            match v {
                [a, b] if a.is_finite() && b.is_finite() => Ok([*a, *b]),
                [_, _] => Err(format!("a non-finite {what}")),
                _ => Err(format!("{} {what} values, not 2", v.len())),
            }
        };
        let p = two(&self.position, "position")?;
        let v = if velocities {
            two(&self.velocity, "velocity")?
        } else {
            [0.0; 2]
        };
        Ok((p, v))
    }
}

/// `sensor_msgs/msg/Image`. A field missing from a dict reads as zero or empty.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Image {
    /// The stamp.
    pub header: Header,
    /// Rows, px.
    pub height: u32,
    /// Columns, px.
    pub width: u32,
    /// The pixel layout, as ROS 2 names it (`mono8`, `rgb8`, …).
    pub encoding: String,
    /// 1 when a pixel's multi-byte values are big-endian; ratelab writes 0.
    pub is_bigendian: u8,
    /// Bytes per row.
    pub step: u32,
    /// The pixels, row after row: `step × height` bytes (one run of bytes in CDR).
    pub data: ImageData,
}

/// `std_msgs/msg/Float64`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Float64 {
    /// The value (a force, N).
    pub data: f64,
}

/// `rosgraph_msgs/msg/Clock`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Clock {
    /// The time.
    pub clock: Time,
}

/// `value` as CDR little endian after the encapsulation header, into `out` (cleared first).
pub fn cdr<T: Serialize>(value: &T, out: &mut Vec<u8>) {
    out.clear();
    out.extend_from_slice(&CDR_LE_HEADER);
    // Alignment counts from after the encapsulation header (the serializer starts there).
    let mut ser = hiroz_cdr::CdrSerializer::<hiroz_cdr::LittleEndian>::new(out);
    // Plain structs of numbers, strings and sequences: serde cannot fail on them.
    let _ = value.serialize(&mut ser);
}

/// A `T` from CDR with its encapsulation header (`CDR_LE` only), within `max` bytes (the
/// type's [`crate::msg::RosMapped::MAX_ROS_BYTES`], never more than
/// [`crate::limits::MAX_ROS_MESSAGE_BYTES`]), with nothing after it but CDR's padding.
///
/// # Errors
/// One line: too long, not CDR_LE, not valid CDR of `T`, or bytes after it.
pub fn from_cdr<'de, T: Deserialize<'de>>(bytes: &'de [u8], max: usize) -> Result<T, String> {
    let max = max.min(MAX_ROS_MESSAGE_BYTES);
    if bytes.len() > max {
        return Err(limits::refusal(
            format_args!("{} bytes, at most {max} for this type", bytes.len()),
            "MAX_ROS_MESSAGE_BYTES",
        ));
    }
    let body = match bytes {
        [0, 1, _, _, body @ ..] => body,
        [a, b, _, _, ..] => {
            return Err(format!("encapsulation {a:02x} {b:02x}, not CDR_LE (00 01)"))
        }
        _ => return Err("shorter than the 4-byte encapsulation header".into()),
    };
    let (v, used) = hiroz_cdr::from_bytes::<T, hiroz_cdr::LittleEndian>(body)
        .map_err(|e| format!("not valid CDR: {e}"))?;
    // CDR pads to 4; anything more after the value is not this type.
    if body.len() - used > 3 {
        return Err(format!("{} bytes after the message", body.len() - used));
    }
    Ok(v)
}

/// `/clock` at run time `t`, as CDR with its encapsulation header, into `out`.
pub fn encode_clock(t: Nanos, out: &mut Vec<u8>) {
    cdr(&Clock { clock: Time::of(t) }, out);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{ForceMsg, Message, MsgData, MsgType, PositionMsg, StateMsg};

    fn encode(d: &MsgData, stamp: Nanos, out: &mut Vec<u8>) {
        assert!((d.msg_type().ros2().unwrap().encode)(d, stamp, out));
    }
    fn dec(t: MsgType, bytes: &[u8]) -> Result<MsgData, String> {
        (t.ros2().unwrap().decode)(bytes)
    }
    fn force(newtons: f64) -> MsgData {
        MsgData::new(ForceMsg { newtons })
    }
    fn position(cart_pos_m: f64, pole_angle_rad: f64) -> MsgData {
        MsgData::new(PositionMsg {
            cart_pos_m,
            pole_angle_rad,
        })
    }
    fn state(o: StateMsg) -> MsgData {
        MsgData::new(o)
    }

    fn decode<'de, T: Deserialize<'de>>(bytes: &'de [u8]) -> T {
        assert_eq!(bytes[..4], CDR_LE_HEADER);
        let (v, used) = hiroz_cdr::from_bytes::<T, hiroz_cdr::LittleEndian>(&bytes[4..]).unwrap();
        assert_eq!(used, bytes.len() - 4, "no trailing bytes");
        v
    }

    #[test]
    fn what_is_encoded_decodes_back() {
        let mut out = Vec::new();
        encode(&force(-3.5), Nanos(1), &mut out);
        assert_eq!(dec(ForceMsg::TYPE, &out), Ok(force(-3.5)));
        encode(&position(0.25, -0.5), Nanos(1), &mut out);
        assert_eq!(dec(PositionMsg::TYPE, &out), Ok(position(0.25, -0.5)));
        let th = 0.125f64;
        let obs = [0.5, -1.0, th.cos() as f32, th.sin() as f32, 2.0];
        encode(&state(obs), Nanos(1), &mut out);
        assert_eq!(dec(StateMsg::TYPE, &out), Ok(state(obs)));
    }

    #[test]
    fn hostile_messages_are_refused_in_one_line() {
        let mut out = Vec::new();
        encode(&position(0.25, -0.5), Nanos(1), &mut out);
        // A position has no velocities: not a state.
        assert!(dec(StateMsg::TYPE, &out)
            .unwrap_err()
            .contains("0 velocity values"));
        encode(&force(1.0), Nanos(1), &mut out);
        assert!(dec(StateMsg::TYPE, &out).is_err());
        assert!(dec(ForceMsg::TYPE, &out[..6]).is_err());
        assert!(dec(ForceMsg::TYPE, &[1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0])
            .unwrap_err()
            .contains("not CDR_LE"));
        assert!(dec(ForceMsg::TYPE, &[0, 1])
            .unwrap_err()
            .contains("shorter than the 4-byte encapsulation header"));
        // A cartpole type takes 4 KiB at most (its decoded form can be larger than its
        // bytes); an image up to the bound.
        let big = vec![0u8; 4097];
        assert!(dec(ForceMsg::TYPE, &big)
            .unwrap_err()
            .contains("4097 bytes, at most 4096 for this type"));
        let big = vec![0u8; MAX_ROS_MESSAGE_BYTES + 1];
        assert!(dec(crate::msg::ImageMsg::TYPE, &big)
            .unwrap_err()
            .contains(&format!("at most {MAX_ROS_MESSAGE_BYTES} for this type")));
        // A sequence claiming 2^32-1 names in a few bytes: refused, not allocated.
        let mut js = vec![0, 1, 0, 0];
        js.extend_from_slice(&[0; 8]); // stamp
        js.extend_from_slice(&1u32.to_le_bytes()); // frame_id: ""
        js.push(0);
        js.extend_from_slice(&[0; 3]);
        js.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(dec(StateMsg::TYPE, &js).is_err());
        let wrong = JointState {
            header: Header {
                stamp: Time::of(Nanos(0)),
                frame_id: String::new(),
            },
            name: vec!["a".into(), "b".into()],
            position: vec![0.0, 0.0],
            velocity: vec![0.0, 0.0],
            effort: vec![],
        };
        cdr(&wrong, &mut out);
        assert!(dec(StateMsg::TYPE, &out).unwrap_err().contains("names"));
    }

    #[test]
    fn hashes_are_ros_2s() {
        // The values rmw_zenoh uses on Jazzy and later (rosbags' hash_rihs01 gives the same;
        // the integration test checks them against it again).
        assert_eq!(
            clock_type().hash.to_rihs_string(),
            "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"
        );
        assert_eq!(
            joint_state_type().hash.to_rihs_string(),
            "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
        );
        assert_eq!(
            float64_type().hash.to_rihs_string(),
            "RIHS01_705ba9c3d1a09df43737eb67095534de36fd426c0587779bda2bc51fe790182a"
        );
        assert_eq!(
            image_type().hash.to_rihs_string(),
            "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"
        );
        assert_eq!(
            joint_state_type().dds_name(),
            "sensor_msgs::msg::dds_::JointState_"
        );
    }

    #[test]
    fn a_force_is_a_float64() {
        let mut out = Vec::new();
        encode(&force(-3.5), Nanos(1), &mut out);
        assert_eq!(out.len(), 12);
        assert_eq!(out[4..], (-3.5f64).to_le_bytes());
        assert_eq!(decode::<Float64>(&out).data, -3.5);
    }

    #[test]
    fn a_state_is_a_joint_state_with_the_angle_and_the_run_time() {
        let th = 0.1f32;
        let mut out = Vec::new();
        encode(
            &state([0.5, -0.25, th.cos(), th.sin(), 2.0]),
            Nanos(2_500_000_000),
            &mut out,
        );
        let js: JointState = decode(&out);
        assert_eq!(
            js.header.stamp,
            Time {
                sec: 2,
                nanosec: 500_000_000
            }
        );
        assert_eq!(js.name, ["slider", "hinge"]);
        assert_eq!(js.position[0], 0.5);
        assert!((js.position[1] - 0.1).abs() < 1e-6);
        assert_eq!(js.velocity, [-0.25, 2.0]);
        assert!(js.effort.is_empty());
        encode(&position(1.0, -0.2), Nanos(0), &mut out);
        let js: JointState = decode(&out);
        assert_eq!(
            (js.position.as_slice(), js.velocity.len()),
            (&[1.0, -0.2][..], 0)
        );
    }

    #[test]
    fn the_clock_is_run_time() {
        let mut out = Vec::new();
        encode_clock(Nanos(3_000_000_007), &mut out);
        assert_eq!(decode::<Clock>(&out).clock, Time { sec: 3, nanosec: 7 });
    }
}
