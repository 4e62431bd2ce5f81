//! An image's pixels ([`ImageData`]): bytes shared by every holder, below both the
//! messages ([`crate::msg`]) and their ROS 2 types ([`crate::ros_types`]), which hold them.
//! Serialized as one run of bytes (postcard, CDR), or read from a sequence of numbers 0–255
//! (a format without bytes, as JSON).
//!
//! Decoded inside [`decode_within`], pixels that lie in the buffer being decoded are not
//! copied: they are a view of that buffer, which they keep alive. This is how a camera's
//! frame that crossed processes through Zenoh's shared memory reaches its subscriber without
//! a copy (issue 76).
//!
//! A node that makes a large frame can draw it straight into the buffer it will cross in:
//! its output topic lends one ([`PixelBuffer`], from the topic's [`Lender`]: a launch's
//! process lends buffers of its shared-memory pool), as ROS 2 lends a publisher's message
//! (rclcpp's `Publisher::borrow_loaned_message`). The frame is then drawn where it will
//! cross (after the buffer is zeroed), and never copied on its way to another process.

use bytes::Bytes;
use serde::{Deserialize, Serialize};
use std::cell::RefCell;

/// An image's pixels: bytes shared by every holder (cloning it copies a pointer), held in
/// memory of their own or, when decoded inside [`decode_within`], as a view of the buffer
/// they were decoded from (a shared-memory sample's, kept mapped while any holder lives).
#[derive(Clone, PartialEq, Eq, Default)]
pub struct ImageData(Bytes);

impl ImageData {
    /// How many bytes.
    pub fn len(&self) -> usize {
        self.0.len()
    }
    /// Whether it holds no bytes.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    /// The bytes.
    pub fn as_slice(&self) -> &[u8] {
        &self.0
    }
    /// Whether `self` and `other` are the same bytes in memory (one a clone of the other, or
    /// both views of one buffer), not only equal ones.
    pub fn shares(&self, other: &ImageData) -> bool {
        self.0.as_ptr() == other.0.as_ptr() && self.0.len() == other.0.len()
    }
    /// Whether these bytes lie inside `buffer` (a view of it, not a copy).
    pub fn is_within(&self, buffer: &[u8]) -> bool {
        within(buffer, &self.0)
    }
}

impl From<Vec<u8>> for ImageData {
    fn from(v: Vec<u8>) -> ImageData {
        ImageData(Bytes::from(v))
    }
}

impl From<&[u8]> for ImageData {
    fn from(v: &[u8]) -> ImageData {
        ImageData(Bytes::copy_from_slice(v))
    }
}

/// Where a topic's frames may be drawn before they are published ([`PixelBuffer::lent`]):
/// a launch's process lends buffers of its shared-memory pool for a topic that crosses to
/// another process, so that the frame crosses without a copy. Set on a topic with
/// [`crate::msg::AnyTopic::set_lender`].
pub trait Lender: Send + Sync {
    /// A buffer of `len` bytes (what it holds does not matter: [`PixelBuffer::lent`] zeroes
    /// it), or `None` when there is none to lend now (the frame is too small to be worth it,
    /// the pool is full or not made yet): the node then draws into memory of its own, and
    /// the frame is copied once on its way out.
    fn lend(&self, len: usize) -> Option<Box<dyn LentPixels>>;
}

/// A buffer a [`Lender`] lent, being drawn into.
pub trait LentPixels: Send {
    /// Its bytes, to draw into.
    fn bytes_mut(&mut self) -> &mut [u8];
    /// Its bytes.
    fn bytes(&self) -> &[u8];
    /// Done drawing: the bytes, shared from here on (they are never written again), still
    /// in the lender's buffer, which they keep until the last holder lets go.
    fn freeze(self: Box<Self>) -> Bytes;
}

/// A frame's pixels being drawn, before they are published as [`ImageData`]: every byte 0
/// to start with, in a buffer a topic lent ([`PixelBuffer::lent`]) or in memory of their own
/// ([`PixelBuffer::zeroed`]). `PixelBuffer` derefs to `[u8]`; `ImageData::from` ends the
/// drawing without copying a byte.
pub struct PixelBuffer(Drawn);

enum Drawn {
    Own(Vec<u8>),
    Lent(Box<dyn LentPixels>),
}

impl PixelBuffer {
    /// `len` bytes of memory of their own, every one 0.
    pub fn zeroed(len: usize) -> PixelBuffer {
        PixelBuffer(Drawn::Own(vec![0; len]))
    }

    /// `len` bytes, every one 0: lent by `lender` when it has a buffer of that length to
    /// lend (zeroed here: a pool's buffer may hold an earlier frame, and a frame must not
    /// depend on where it was drawn), else [`PixelBuffer::zeroed`].
    pub fn lent(lender: Option<&dyn Lender>, len: usize) -> PixelBuffer {
        match lender.and_then(|l| l.lend(len)) {
            Some(mut buf) if buf.bytes().len() == len => {
                buf.bytes_mut().fill(0);
                PixelBuffer(Drawn::Lent(buf))
            }
            _ => PixelBuffer::zeroed(len),
        }
    }

    /// Whether a lender lent these bytes.
    pub fn is_lent(&self) -> bool {
        matches!(self.0, Drawn::Lent(_))
    }
}

impl std::ops::Deref for PixelBuffer {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match &self.0 {
            Drawn::Own(v) => v,
            Drawn::Lent(b) => b.bytes(),
        }
    }
}

impl std::ops::DerefMut for PixelBuffer {
    fn deref_mut(&mut self) -> &mut [u8] {
        match &mut self.0 {
            Drawn::Own(v) => v,
            Drawn::Lent(b) => b.bytes_mut(),
        }
    }
}

impl From<PixelBuffer> for ImageData {
    /// The drawn pixels, shared from here on: not copied.
    fn from(px: PixelBuffer) -> ImageData {
        match px.0 {
            Drawn::Own(v) => ImageData::from(v),
            Drawn::Lent(b) => ImageData(b.freeze()),
        }
    }
}

impl std::fmt::Debug for PixelBuffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let whose = if self.is_lent() { "lent" } else { "own" };
        write!(f, "<{} bytes, {whose}>", self.len())
    }
}

thread_local! {
    /// The buffer [`decode_within`] is decoding on this thread, if any.
    static BACKING: RefCell<Option<Bytes>> = const { RefCell::new(None) };
}

/// `part` lies inside `whole` (an address range test; an empty `part` never does).
fn within(whole: &[u8], part: &[u8]) -> bool {
    let (w, p) = (whole.as_ptr_range(), part.as_ptr_range());
    !part.is_empty() && w.start <= p.start && p.end <= w.end
}

/// Run `decode` (which decodes from `buffer`'s bytes) so that every [`ImageData`] it
/// decodes from a borrowed run of bytes inside `buffer` is a view of `buffer` rather than a
/// copy: it keeps `buffer`'s memory alive (a clone of `buffer` is a reference count, not a
/// copy). Pixels from anywhere else, or decoded from a format that does not lend its bytes,
/// are copied as always. Nested calls keep the outer buffer once the inner one returns.
pub fn decode_within<R>(buffer: &Bytes, decode: impl FnOnce() -> R) -> R {
    struct Restore(Option<Bytes>);
    impl Drop for Restore {
        fn drop(&mut self) {
            let outer = self.0.take();
            BACKING.with(|b| *b.borrow_mut() = outer);
        }
    }
    let _restore = Restore(BACKING.with(|b| b.borrow_mut().replace(buffer.clone())));
    decode()
}

/// `v` as pixels: a view of the buffer being decoded when it lies inside it, else a copy.
fn borrowed(v: &[u8]) -> ImageData {
    let view = BACKING.with(|b| {
        let b = b.borrow();
        let buffer = b.as_ref()?;
        within(buffer, v).then(|| buffer.slice_ref(v))
    });
    ImageData(view.unwrap_or_else(|| Bytes::copy_from_slice(v)))
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
    /// From bytes (copied once, straight from a borrowed buffer: postcard's, CDR's; not
    /// copied at all from the buffer [`decode_within`] names) or a sequence of numbers 0–255
    /// (a format without bytes, as JSON).
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
        Ok(ImageData::from(v))
    }
    fn visit_borrowed_bytes<E: serde::de::Error>(self, v: &'de [u8]) -> Result<ImageData, E> {
        Ok(borrowed(v))
    }
    fn visit_byte_buf<E: serde::de::Error>(self, v: Vec<u8>) -> Result<ImageData, E> {
        Ok(ImageData::from(v))
    }
    fn visit_seq<A: serde::de::SeqAccess<'de>>(self, seq: A) -> Result<ImageData, A::Error> {
        serde_bytes::ByteBuf::deserialize(serde::de::value::SeqAccessDeserializer::new(seq))
            .map(|b| ImageData::from(b.into_vec()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_decoded_within_their_buffer_are_a_view_of_it() {
        let img = ImageData::from(vec![7u8; 1000]);
        let wire = Bytes::from(postcard::to_allocvec(&img).unwrap());
        let view: ImageData = decode_within(&wire, || postcard::from_bytes(&wire).unwrap());
        assert_eq!(view, img);
        assert!(view.is_within(&wire), "a view, not a copy");
        // Outside decode_within, or from another buffer, the same bytes are copied.
        let copy: ImageData = postcard::from_bytes(&wire).unwrap();
        assert!(!copy.is_within(&wire));
        let other = Bytes::from(wire.to_vec());
        let copy: ImageData = decode_within(&other, || postcard::from_bytes(&wire).unwrap());
        assert!(!copy.is_within(&wire) && !copy.is_within(&other));
        assert_eq!(copy, img);
    }

    #[test]
    fn a_view_keeps_its_buffer_alive_and_the_outer_buffer_comes_back() {
        let img = ImageData::from(vec![1u8, 2, 3, 4]);
        let outer = Bytes::from(postcard::to_allocvec(&img).unwrap());
        let inner = Bytes::from(postcard::to_allocvec(&img).unwrap());
        let (a, b): (ImageData, ImageData) = decode_within(&outer, || {
            let a = decode_within(&inner, || postcard::from_bytes(&inner).unwrap());
            (a, postcard::from_bytes(&outer).unwrap())
        });
        assert!(a.is_within(&inner) && b.is_within(&outer));
        drop((outer, inner));
        assert_eq!(a.as_slice(), &[1, 2, 3, 4]);
        assert_eq!(b.as_slice(), &[1, 2, 3, 4]);
        // An empty run is never a view; clones share their bytes.
        assert!(!ImageData::default().is_within(&[0u8; 4]));
        assert!(a.shares(&a.clone()) && !a.shares(&b));
    }

    /// A lender of buffers of its own, each `len` bytes of 0xAA (as a pool's buffer may
    /// hold an earlier frame), or `wrong` bytes long.
    struct Lends {
        wrong: Option<usize>,
    }

    struct Lent(Vec<u8>);

    impl LentPixels for Lent {
        fn bytes_mut(&mut self) -> &mut [u8] {
            &mut self.0
        }
        fn bytes(&self) -> &[u8] {
            &self.0
        }
        fn freeze(self: Box<Self>) -> Bytes {
            Bytes::from(self.0)
        }
    }

    impl Lender for Lends {
        fn lend(&self, len: usize) -> Option<Box<dyn LentPixels>> {
            Some(Box::new(Lent(vec![0xAA; self.wrong.unwrap_or(len)])))
        }
    }

    #[test]
    fn a_frame_drawn_into_a_lent_buffer_is_published_without_a_copy() {
        let lender = Lends { wrong: None };
        let mut px = PixelBuffer::lent(Some(&lender), 6);
        assert!(px.is_lent() && px.len() == 6);
        assert!(
            px.iter().all(|&b| b == 0),
            "zeroed, whatever the buffer held"
        );
        px[2] = 9;
        let at = px.as_ptr();
        let img = ImageData::from(px);
        assert_eq!(img.as_slice(), &[0, 0, 9, 0, 0, 0]);
        assert_eq!(img.as_slice().as_ptr(), at, "the lent bytes themselves");
        // No lender, or one that lends a buffer of another length: memory of its own.
        let own = PixelBuffer::lent(None, 4);
        assert!(!own.is_lent() && *own == [0u8; 4]);
        let wrong = Lends { wrong: Some(5) };
        let px = PixelBuffer::lent(Some(&wrong), 4);
        assert!(!px.is_lent() && px.len() == 4);
        assert_eq!(format!("{px:?}"), "<4 bytes, own>");
    }

    #[test]
    fn a_topic_lends_its_publisher_what_its_lender_gives() {
        use crate::msg::{AnyTopic, ImageMsg, Message};
        use std::sync::Arc;
        let topic = AnyTopic::new("/image", ImageMsg::TYPE, 1).unwrap();
        assert!(!topic.loan_pixels(8).is_lent(), "no lender yet");
        assert!(topic.set_lender(Arc::new(Lends { wrong: None })));
        assert!(topic.loan_pixels(8).is_lent());
        // A lender is set once.
        assert!(!topic.set_lender(Arc::new(Lends { wrong: None })));
        // A topic with two subscriptions lends as one.
        let fan =
            AnyTopic::with_subscriptions("/image", ImageMsg::TYPE, 1, Default::default(), 0, 2);
        let fan = fan.unwrap();
        assert!(fan.set_lender(Arc::new(Lends { wrong: None })));
        assert!(fan.loan_pixels(8).is_lent());
    }

    #[test]
    fn a_decode_that_panics_leaves_no_buffer_behind() {
        let img = ImageData::from(vec![9u8; 64]);
        let wire = Bytes::from(postcard::to_allocvec(&img).unwrap());
        let caught = std::panic::catch_unwind(|| decode_within(&wire, || panic!("a bad decode")));
        assert!(caught.is_err());
        let copy: ImageData = postcard::from_bytes(&wire).unwrap();
        assert!(!copy.is_within(&wire), "no buffer is named after the panic");
    }
}
