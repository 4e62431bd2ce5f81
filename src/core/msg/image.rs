//! The **image** message: a camera's frame, laid out as ROS 2's `sensor_msgs/msg/Image`
//! (height, width, encoding, step, data). Its pixels are shared, never copied per
//! subscriber: every subscriber of a topic in one process holds the same bytes
//! ([`ImageData`] is a reference-counted buffer), and across processes they travel once per
//! sample (postcard writes them as one run of bytes). ROS 2 sees it as
//! `sensor_msgs/msg/Image` ([`crate::ros_types::Image`]), stamped with its publish time.

use super::{Field, Message, RosCodec, RosMapped, Value};
pub use crate::pixels::ImageData;
use crate::ros_types::{image_type, Header, Image, RosType, Time};
use crate::time::Nanos;
use serde::{Deserialize, Serialize};

/// A camera's frame (ROS 2's `sensor_msgs/msg/Image` without its header: ratelab stamps
/// every message).
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
pub struct ImageMsg {
    /// Rows, px.
    pub height: u32,
    /// Columns, px.
    pub width: u32,
    /// How a pixel is laid out, as ROS 2 names it (`mono8`: one byte of brightness).
    pub encoding: String,
    /// Bytes per row (`width` for `mono8`).
    pub step: u32,
    /// The pixels, row after row: `step × height` bytes.
    pub data: ImageData,
}

impl ImageMsg {
    /// Is it whole: `step × height` bytes, at least a byte per pixel?
    pub fn is_consistent(&self) -> bool {
        let rows = self.height as usize;
        self.step >= self.width && self.data.len() == self.step as usize * rows
    }
}

impl Message for ImageMsg {
    const NAME: &'static str = "image";
    const CLASS: &'static str = "Image";
    const DOC: &'static str =
        "A camera's frame, as sensor_msgs/Image: height, width, encoding, step, data.";
    const FIELDS: &'static [Field] = &[
        Field::integer("height", "px", "rows"),
        Field::integer("width", "px", "columns"),
        Field::text("encoding", "pixel layout (mono8: a byte of brightness)"),
        Field::integer("step", "B", "bytes per row"),
        Field::bytes("data", "pixel bytes", "the pixels, row after row"),
    ];
    /// `[height, width, step]`.
    fn to_fields(&self) -> Vec<f64> {
        vec![
            f64::from(self.height),
            f64::from(self.width),
            f64::from(self.step),
        ]
    }
    /// An image of no pixels with these dimensions.
    fn from_fields(f: &[f64]) -> Self {
        let dim = |x: f64| {
            if x.is_finite() && x >= 0.0 {
                x.min(f64::from(u32::MAX)) as u32
            } else {
                0
            }
        };
        ImageMsg {
            height: dim(f[0]),
            width: dim(f[1]),
            encoding: String::new(),
            step: dim(f[2]),
            data: ImageData::default(),
        }
    }
    /// From `[height, width, encoding, step, data]` (as [`crate::msg::MsgType::from_values`]
    /// checks them).
    fn from_values(v: &[Value]) -> Self {
        let mut img = ImageMsg::from_fields(&[
            v.first().map_or(0.0, number),
            v.get(1).map_or(0.0, number),
            v.get(3).map_or(0.0, number),
        ]);
        if let Some(Value::Text(t)) = v.get(2) {
            img.encoding = t.clone();
        }
        if let Some(Value::Bytes(b)) = v.get(4) {
            img.data = b.clone();
        }
        img
    }
    fn ros2() -> Option<RosCodec> {
        Some(RosCodec::of::<Self>())
    }
    fn to_values(&self) -> Vec<Value> {
        vec![
            Value::Number(f64::from(self.height)),
            Value::Number(f64::from(self.width)),
            Value::Text(self.encoding.clone()),
            Value::Number(f64::from(self.step)),
            Value::Bytes(self.data.clone()),
        ]
    }
}

impl RosMapped for ImageMsg {
    type Ros = Image;
    /// A frame may be as large as any message from ROS 2 (a 4K RGB image is 25 MB).
    const MAX_ROS_BYTES: usize = crate::limits::MAX_ROS_MESSAGE_BYTES;
    fn ros_type() -> &'static RosType {
        image_type()
    }
    fn to_ros(&self, stamp: Nanos) -> Image {
        Image {
            header: Header {
                stamp: Time::of(stamp),
                frame_id: String::new(),
            },
            height: self.height,
            width: self.width,
            encoding: self.encoding.clone(),
            is_bigendian: 0,
            step: self.step,
            data: self.data.clone(),
        }
    }
    /// A whole image (`step × height` bytes, `step ≥ width`) whose multi-byte pixels, if
    /// any, are little-endian (`is_bigendian` is not read for an encoding of bytes:
    /// `mono8`, `rgb8`); the header is not read (ratelab stamps every message).
    fn from_ros(img: Image) -> Result<Self, String> {
        if img.is_bigendian != 0 && has_multi_byte_channels(&img.encoding) {
            return Err(format!(
                "an Image of {} with big-endian pixels (is_bigendian 1): ratelab reads little-endian ones",
                crate::text::printable(&img.encoding)
            ));
        }
        let msg = ImageMsg {
            height: img.height,
            width: img.width,
            encoding: img.encoding,
            step: img.step,
            data: img.data,
        };
        if msg.step < msg.width {
            return Err(format!(
                "an Image whose step ({} bytes a row) is less than its width ({} px)",
                msg.step, msg.width
            ));
        }
        if !msg.is_consistent() {
            return Err(format!(
                "an Image of {} bytes, not step × height = {} × {}",
                msg.data.len(),
                msg.step,
                msg.height
            ));
        }
        Ok(msg)
    }
}

/// Does a pixel of ROS 2's `encoding` hold values of more than one byte (`mono16`, `16UC1`,
/// `32FC1`, `bayer_rggb16`), whose byte order matters?
fn has_multi_byte_channels(encoding: &str) -> bool {
    ["16", "32", "64"]
        .iter()
        .any(|bits| encoding.contains(bits))
}

/// A number value's number (0 for another kind).
fn number(v: &Value) -> f64 {
    match v {
        Value::Number(x) => *x,
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::MsgData;

    #[test]
    fn an_image_crosses_the_wire_whole_and_its_copies_share_the_pixels() {
        let pixels: Vec<u8> = (0..1_048_576u32).map(|i| (i % 251) as u8).collect();
        let img = ImageMsg {
            height: 1024,
            width: 1024,
            encoding: "mono8".into(),
            step: 1024,
            data: pixels.into(),
        };
        assert!(img.is_consistent());
        // A copy (a subscriber's) holds the same bytes, not a copy of them.
        let copy = img.clone();
        assert!(img.data.shares(&copy.data));
        // The wire: the pixels as one run of bytes, after a few of header.
        let data = MsgData::new(img.clone());
        let bytes = data.to_bytes();
        assert!(bytes.len() < 1_048_576 + 32, "{} bytes", bytes.len());
        let back = ImageMsg::TYPE.decode(&bytes).unwrap();
        assert_eq!(back, data);
        assert_eq!(
            data.describe(),
            "image: height=1024 px, width=1024 px, encoding=\"mono8\", step=1024 B, data=<1048576 bytes>"
        );
        // Cut short, or with bytes after it: refused, in one line.
        assert!(ImageMsg::TYPE.decode(&bytes[..bytes.len() - 1]).is_err());
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(ImageMsg::TYPE
            .decode(&longer)
            .unwrap_err()
            .contains("after"));
        assert!(!ImageMsg::TYPE.is_numeric());
        // From its values, as a Python node publishes it; a value of the wrong kind is
        // named.
        let again = ImageMsg::TYPE.from_values(&img.to_values()).unwrap();
        assert_eq!(again, data);
        let mut wrong = img.to_values();
        wrong[2] = Value::Number(1.0);
        let e = ImageMsg::TYPE.from_values(&wrong).unwrap_err();
        assert!(e.contains("Image.encoding holds Text"), "{e}");
        // ROS 2's sensor_msgs/Image, stamped: the pixels as one run of bytes after the
        // header and the four small fields (rosbags reads it: tests/it/ros2.rs).
        let codec = ImageMsg::TYPE.ros2().unwrap();
        let mut cdr = Vec::new();
        assert!((codec.encode)(&data, Nanos(1_500_000_000), &mut cdr));
        assert_eq!(cdr.len(), 4 + 8 + 4 + 4 + 4 + 4 + 8 + 4 + 4 + 4 + 1_048_576);
        assert_eq!(cdr[cdr.len() - 1_048_576..], *img.data.as_slice());
        assert_eq!((codec.decode)(&cdr), Ok(data.clone()));
        let whole = img.to_ros(Nanos(0));
        let refused = |i: Image| ImageMsg::from_ros(i).unwrap_err();
        let short = Image {
            data: vec![0; 10].into(),
            ..whole.clone()
        };
        assert!(refused(short).contains("10 bytes, not step × height = 1024 × 1024"));
        let narrow = Image {
            step: 512,
            data: vec![0; 512 * 1024].into(),
            ..whole.clone()
        };
        assert!(refused(narrow).contains("step (512 bytes a row) is less than its width (1024 px)"));
        // Byte order matters only for pixels of more than a byte.
        let big_endian = Image {
            is_bigendian: 1,
            ..whole.clone()
        };
        assert!(
            ImageMsg::from_ros(big_endian).is_ok(),
            "mono8 has no byte order"
        );
        let big_endian = Image {
            is_bigendian: 1,
            encoding: "mono16".into(),
            step: 2048,
            data: vec![0; 2048 * 1024].into(),
            ..whole
        };
        assert!(refused(big_endian).contains("mono16 with big-endian pixels"));
        assert!(ImageMsg::TYPE
            .from_values(&wrong[..4])
            .unwrap_err()
            .contains("5 fields"));
    }
}
