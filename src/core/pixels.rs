//! An image's pixels ([`ImageData`]): bytes shared by every holder, below both the
//! messages ([`crate::msg`]) and their ROS 2 types ([`crate::ros_types`]), which hold them.
//! Serialized as one run of bytes (postcard, CDR), or read from a sequence of numbers 0–255
//! (a format without bytes, as JSON).

use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// An image's pixels: bytes shared by every holder (cloning it copies a pointer).
#[derive(Clone, PartialEq, Eq, Default)]
pub struct ImageData(pub Arc<[u8]>);

impl ImageData {
    /// How many bytes.
    pub fn len(&self) -> usize {
        self.0.len()
    }
    /// None?
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// The bytes.
    pub fn as_slice(&self) -> &[u8] {
        &self.0
    }
}

impl From<Vec<u8>> for ImageData {
    fn from(v: Vec<u8>) -> ImageData {
        ImageData(Arc::from(v))
    }
}

impl std::fmt::Debug for ImageData {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "<{} bytes>", self.0.len())
    }
}

impl Serialize for ImageData {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(&self.0)
    }
}

impl<'de> Deserialize<'de> for ImageData {
    /// From bytes (copied once, straight from a borrowed buffer: postcard's, CDR's) or a
    /// sequence of numbers 0–255 (a format without bytes, as JSON).
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<ImageData, D::Error> {
        d.deserialize_bytes(PixelsVisitor)
    }
}

struct PixelsVisitor;

impl<'de> serde::de::Visitor<'de> for PixelsVisitor {
    type Value = ImageData;
    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str("an image's bytes")
    }
    fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<ImageData, E> {
        Ok(ImageData(Arc::from(v)))
    }
    fn visit_byte_buf<E: serde::de::Error>(self, v: Vec<u8>) -> Result<ImageData, E> {
        Ok(ImageData::from(v))
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, seq: A) -> Result<ImageData, A::Error> {
        serde_bytes::ByteBuf::deserialize(serde::de::value::SeqAccessDeserializer::new(seq))
            .map(|b| ImageData::from(b.into_vec()))
    }
}
