//! Coders whose state spans frames (issue 19 §1): a video codec predicts
//! each picture from the ones before it, so the sender keeps one encoder per
//! stream and the receiver one decoder, fed every payload in the order it
//! was encoded. protocol names the codec ([`Codec::H264`]) and carries its
//! payloads; the coders implement these traits outside it (crate `video`),
//! so this crate stays free of codec libraries.
//!
//! A decoder that misses a payload cannot decode the next ones until a
//! keyframe: the receiver asks for one ([`crate::wire::KeyframeRequest`]).

use half::f16;

use super::Codec;
use crate::FrameSize;

/// Bytes a coder may add to an access unit, beyond the raw frame's length,
/// in [`Codec::encoded_len_range`].
pub const MAX_OVERHEAD: u64 = 64 * 1024;

/// What a coder reports for one frame.
pub type StreamError = Box<dyn std::error::Error + Send + Sync>;

/// Encodes one stream's colour, frame after frame. `Send`: a frame's
/// colour is coded on a thread of its own while the other buffers are
/// coded beside it ([`crate::assemble::encode_frame_with`]).
pub trait ColorStreamEncoder: Send {
    /// The codec it writes.
    fn codec(&self) -> Codec;
    /// The payload of `color`, a frame of `size` (linear RGBA).
    fn encode_color(&mut self, size: FrameSize, color: &[[f16; 4]])
    -> Result<Vec<u8>, StreamError>;
}

/// Decodes one stream's colour payloads, in the order they were encoded.
/// `Send`, as the encoder is: colour is decoded beside the other buffers.
pub trait ColorStreamDecoder: Send {
    /// The codec it reads.
    fn codec(&self) -> Codec;
    /// Decodes `payload` into `out` as a frame of `size` (linear RGBA,
    /// `size.pixels()` values).
    fn decode_color(
        &mut self,
        payload: &[u8],
        size: FrameSize,
        out: &mut Vec<[f16; 4]>,
    ) -> Result<(), StreamError>;
}
