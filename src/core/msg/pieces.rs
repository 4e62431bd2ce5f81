//! A payload's wire bytes in pieces, not one run: written to a sink piece by piece
//! ([`MsgData::encode_pieces`](super::MsgData::encode_pieces)), so that a run of bytes that
//! already lies where it will cross (a frame drawn into a lent shared-memory buffer,
//! [`crate::pixels::PixelBuffer`]) is handed on whole rather than copied; and read from
//! several runs ([`MsgType::decode_pieces`](super::MsgType::decode_pieces)), as a sample
//! that crossed in pieces arrives. The bytes are postcard's, the same as
//! [`MsgData::to_bytes`](super::MsgData::to_bytes) in one run.

use super::{Message, MsgData, MAX_PAYLOAD_BYTES};
use postcard::de_flavors::Flavor as DeFlavor;
use postcard::ser_flavors::Flavor as SerFlavor;

/// Postcard's output handed to a sink: each byte and each run of bytes as postcard writes
/// them (a field of bytes, as [`crate::pixels::ImageData`], is one run: its own bytes).
pub(super) struct ToSink<'s>(pub(super) &'s mut dyn FnMut(&[u8]));

impl SerFlavor for ToSink<'_> {
    type Output = ();
    fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
        (self.0)(&[byte]);
        Ok(())
    }
    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        (self.0)(bytes);
        Ok(())
    }
    fn finalize(self) -> postcard::Result<()> {
        Ok(())
    }
}

/// Postcard's input from several runs of bytes, read in order. A run of bytes postcard
/// asks for whole (a field of bytes, a string, a float) must lie inside one piece, as
/// [`MsgData::encode_pieces`]'s sinks keep a lent buffer's bytes; one that straddles two
/// pieces is refused ([`PiecesError::Straddles`]), and the caller reads the pieces joined
/// instead.
///
/// [`MsgData::encode_pieces`]: super::MsgData::encode_pieces
pub(super) struct FromPieces<'de> {
    /// The pieces not yet begun.
    rest: &'de [&'de [u8]],
    /// What is left of the current piece.
    now: &'de [u8],
    /// A run of bytes was asked for across two pieces.
    straddled: bool,
}

/// What is left when [`FromPieces`] is done.
pub(super) struct Left {
    /// The bytes not read.
    pub(super) bytes: usize,
    /// Whether a run of bytes was asked for across two pieces (refused).
    pub(super) straddled: bool,
}

/// Why a payload in pieces was not read ([`MsgType::decode_pieces`](super::MsgType::decode_pieces)).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PiecesError {
    /// A run postcard reads whole (a field of bytes, a string, a float) lies across two
    /// pieces: the pieces joined may still be read.
    Straddles,
    /// Refused, as in one run: too long, not this type, or bytes after its end (one line).
    Refused(String),
}

impl std::fmt::Display for PiecesError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PiecesError::Straddles => f.write_str("a run of bytes across two pieces"),
            PiecesError::Refused(why) => f.write_str(why),
        }
    }
}

impl<'de> FromPieces<'de> {
    pub(super) fn new(pieces: &'de [&'de [u8]]) -> FromPieces<'de> {
        FromPieces {
            rest: pieces,
            now: &[],
            straddled: false,
        }
    }

    /// Move past empty pieces: `now` is empty only at the end.
    fn settle(&mut self) {
        while self.now.is_empty() {
            let Some((first, rest)) = self.rest.split_first() else {
                return;
            };
            (self.now, self.rest) = (first, rest);
        }
    }

    /// The bytes not yet read.
    pub(super) fn left(&self) -> usize {
        self.now.len() + self.rest.iter().map(|p| p.len()).sum::<usize>()
    }
}

impl<'de> DeFlavor<'de> for FromPieces<'de> {
    type Remainder = Left;
    type Source = &'de [&'de [u8]];

    fn pop(&mut self) -> postcard::Result<u8> {
        self.settle();
        let (&b, rest) = self
            .now
            .split_first()
            .ok_or(postcard::Error::DeserializeUnexpectedEnd)?;
        self.now = rest;
        Ok(b)
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.left())
    }

    fn try_take_n(&mut self, ct: usize) -> postcard::Result<&'de [u8]> {
        if ct == 0 {
            return Ok(&[]);
        }
        self.settle();
        if ct > self.left() {
            return Err(postcard::Error::DeserializeUnexpectedEnd);
        }
        if ct > self.now.len() {
            self.straddled = true;
            return Err(postcard::Error::DeserializeBadEncoding);
        }
        let (taken, rest) = self.now.split_at(ct);
        self.now = rest;
        Ok(taken)
    }

    fn finalize(self) -> postcard::Result<Left> {
        Ok(Left {
            bytes: self.left(),
            straddled: self.straddled,
        })
    }
}

/// A message of type `M` from its wire bytes in `pieces`
/// ([`MsgType::decode_pieces`](super::MsgType::decode_pieces)).
pub(super) fn from_pieces<M: Message>(pieces: &[&[u8]]) -> Result<MsgData, PiecesError> {
    let len: usize = pieces.iter().map(|p| p.len()).sum();
    if len > MAX_PAYLOAD_BYTES {
        return Err(PiecesError::Refused(format!(
            "a {} payload of {len} bytes (at most {MAX_PAYLOAD_BYTES})",
            M::NAME
        )));
    }
    let mut de = postcard::Deserializer::from_flavor(FromPieces::new(pieces));
    let decoded = M::deserialize(&mut de);
    // The flavor's finalize cannot fail.
    let left = de
        .finalize()
        .map_err(|e| PiecesError::Refused(e.to_string()))?;
    match decoded {
        Err(_) if left.straddled => Err(PiecesError::Straddles),
        Err(e) => Err(PiecesError::Refused(format!(
            "not a {} payload: {e}",
            M::NAME
        ))),
        Ok(m) if left.bytes == 0 => Ok(MsgData::new(m)),
        Ok(_) => Err(PiecesError::Refused(format!(
            "{} bytes after a {} payload",
            left.bytes,
            M::NAME
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::image::ImageMsg;
    use crate::msg::{Message, MsgData};
    use crate::pixels::ImageData;

    fn frame() -> ImageMsg {
        ImageMsg {
            height: 2,
            width: 3,
            encoding: "mono8".into(),
            step: 3,
            data: ImageData::from(vec![1u8, 2, 3, 4, 5, 6]),
        }
    }

    #[test]
    fn pieces_joined_are_the_one_run_and_a_field_of_bytes_is_one_piece() {
        let m = MsgData::new(frame());
        let mut pieces: Vec<Vec<u8>> = Vec::new();
        m.encode_pieces(&mut |p| pieces.push(p.to_vec())).unwrap();
        assert_eq!(pieces.concat(), m.to_bytes());
        let pixels = m.get::<ImageMsg>().unwrap().data.as_slice();
        assert!(
            pieces.iter().any(|p| p == pixels),
            "the pixels are handed on as one run: {pieces:?}"
        );
    }

    #[test]
    fn a_payload_in_pieces_decodes_as_in_one_run() {
        let m = MsgData::new(frame());
        let wire = m.to_bytes();
        // Cut just before the pixels (6 bytes at the end), and once more inside the head.
        let at = wire.len() - 6;
        let pieces: [&[u8]; 4] = [&wire[..2], &wire[2..at], &[], &wire[at..]];
        let back = ImageMsg::TYPE.decode_pieces(&pieces).unwrap();
        assert_eq!(back, m);
        // A cut inside the pixels: refused as straddling, so the caller joins them.
        let cut: [&[u8]; 2] = [&wire[..at + 2], &wire[at + 2..]];
        let e = ImageMsg::TYPE.decode_pieces(&cut).unwrap_err();
        assert_eq!(e, PiecesError::Straddles);
        // Too short, or bytes after the end: refused as in one run.
        let short: [&[u8]; 2] = [&wire[..at], &wire[at..wire.len() - 1]];
        assert!(ImageMsg::TYPE.decode_pieces(&short).is_err());
        let long: [&[u8]; 2] = [&wire, &[0]];
        let e = ImageMsg::TYPE.decode_pieces(&long).unwrap_err();
        assert!(e.to_string().contains("1 bytes after"), "{e}");
    }
}
