//! What the stream does to a fed frame before the generator sees it: with
//! [`BufferSet::Compact`], depth and motion are quantised by the stream's
//! codecs (issue 19), so `eval --geometry compact` encodes and decodes
//! every fed frame as `serve` and `connect` do, coded against the fed frame
//! before it (the previous frame a server at the fed rate would send).
//! Colour stays as rendered (raw f16).

use protocol::assemble::encode_frame_after;
use protocol::codec::DEFAULT_ZSTD_LEVEL;
use protocol::wire::{BufferSet, StreamBuffer};
use protocol::{Codec, Frame, FrameMeta};

/// The stream's codecs between the renderer and the generator.
pub struct Transport {
    /// The buffers to code fed frames with; `None` when they are lossless.
    buffers: Option<[StreamBuffer; 3]>,
}

impl Transport {
    /// Fed frames through `set`'s codecs.
    pub fn new(set: BufferSet) -> Self {
        Self {
            buffers: match set {
                BufferSet::Compact => Some(set.buffers(Codec::Raw)),
                BufferSet::Lossless => None,
            },
        }
    }

    /// `frame` as a client decodes it, when `previous` was the frame sent
    /// before it.
    pub fn carry(&self, frame: Frame, previous: Option<&FrameMeta>) -> anyhow::Result<Frame> {
        let Some(buffers) = &self.buffers else {
            return Ok(frame);
        };
        let encoded = encode_frame_after(&frame, previous, buffers, DEFAULT_ZSTD_LEVEL)?;
        Ok(encoded.decode()?)
    }
}
