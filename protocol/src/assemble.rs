//! One frame on the wire: encoding a [`Frame`] into a [`FrameHeader`] plus
//! [`BufferPayload`]s, and the sans-IO [`FrameAssembler`] that checks and
//! reassembles them on the receiving side (one per per-frame stream).

use std::borrow::Cow;

use crate::codec::stream::{ColorStreamDecoder, ColorStreamEncoder};
use crate::codec::{self, Codec, CodecError, depth, motion};
use crate::frame::{BufferDesc, BufferKind, Frame, FrameMeta};
use crate::wire::{
    self, BufferPayload, Decoder, FrameHeader, Message, MessageKind, StreamBuffer, WireError,
};
use crate::{Limits, ValidationError};

/// A frame stream that cannot be built or reassembled.
#[derive(Debug, thiserror::Error)]
pub enum AssembleError {
    /// The bytes are not valid messages.
    #[error(transparent)]
    Wire(#[from] WireError),
    /// A frame or buffer list breaks the data contract.
    #[error(transparent)]
    Invalid(#[from] ValidationError),
    /// A payload failed to encode or decode.
    #[error("{kind:?} buffer: {source}")]
    Codec {
        /// The buffer.
        kind: BufferKind,
        /// What the codec reported.
        #[source]
        source: CodecError,
    },
    /// A message that does not belong on a frame stream, or out of order.
    #[error("unexpected {0:?} on a frame stream")]
    Unexpected(MessageKind),
    /// A payload arrived before the header.
    #[error("payload before the frame header")]
    HeaderMissing,
    /// An earlier error ended this stream.
    #[error("the frame stream already failed")]
    Poisoned,
    /// A payload belongs to another frame.
    #[error("payload for frame {got} on the stream of frame {expected}")]
    FrameIndexMismatch {
        /// The header's index.
        expected: u64,
        /// The payload's index.
        got: u64,
    },
    /// A payload for a buffer the header did not list.
    #[error("payload for unlisted buffer {0:?}")]
    UnlistedBuffer(BufferKind),
    /// The same buffer twice.
    #[error("payload for {0:?} received twice")]
    DuplicatePayload(BufferKind),
    /// A payload's length differs from the header's.
    #[error("{kind:?} payload is {got} bytes, header said {expected}")]
    LengthMismatch {
        /// The buffer.
        kind: BufferKind,
        /// From the header.
        expected: u64,
        /// Received.
        got: u64,
    },
    /// The stream ended before every listed buffer arrived.
    #[error("stream ended with {missing:?} missing")]
    Incomplete {
        /// Buffers not received.
        missing: Vec<BufferKind>,
    },
}

/// A frame whose header and every payload arrived and were checked against
/// each other; the codecs have not run yet, so a receiver can drop a stale
/// frame before paying for decoding.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedFrame {
    /// The header.
    pub header: FrameHeader,
    /// One payload per header buffer, in the header's order.
    pub payloads: Vec<BufferPayload>,
}

impl EncodedFrame {
    /// Runs the codecs and builds the [`Frame`].
    ///
    /// The header is validated again and payloads must match it one to one,
    /// so an `EncodedFrame` built by hand is held to the same rules as one
    /// from the [`FrameAssembler`]; the result is a validated [`Frame`].
    /// A frame whose colour is video-coded needs the stream's decoder:
    /// see [`EncodedFrame::decode_with`].
    pub fn decode(&self) -> Result<Frame, AssembleError> {
        self.decode_with(None)
    }

    /// [`EncodedFrame::decode`], with the stream's colour decoder for a
    /// codec whose state spans frames ([`codec::stream`]). The decoder runs
    /// on a thread of its own beside the other buffers' decoding and is fed
    /// every frame whose header and payloads checked out, even when another
    /// buffer fails; its error is the one returned when both fail.
    pub fn decode_with(
        &self,
        mut color: Option<&mut dyn ColorStreamDecoder>,
    ) -> Result<Frame, AssembleError> {
        let limits = Limits::default();
        Message::FrameHeader(self.header.clone())
            .validate(&limits)
            .map_err(AssembleError::Invalid)?;
        let meta = self.header.meta;
        if self.payloads.len() != self.header.buffers.len() {
            let missing = self
                .header
                .buffers
                .iter()
                .skip(self.payloads.len())
                .map(|d| d.kind)
                .collect();
            return Err(AssembleError::Incomplete { missing });
        }
        let mut frame = Frame::empty(meta);
        for (desc, payload) in self.header.buffers.iter().zip(&self.payloads) {
            if payload.kind != desc.kind {
                return Err(AssembleError::UnlistedBuffer(payload.kind));
            }
            if payload.data.len() as u64 != desc.payload_len {
                return Err(AssembleError::LengthMismatch {
                    kind: desc.kind,
                    expected: desc.payload_len,
                    got: payload.data.len() as u64,
                });
            }
        }
        // A video stream's colour is decoded on a thread of its own, beside
        // the other buffers (its decoder is fed whatever they do); motion
        // residuals predict from the decoded depth: they go last.
        let mut order: Vec<_> = self.header.buffers.iter().zip(&self.payloads).collect();
        order.sort_by_key(|(desc, _)| match desc.codec {
            Codec::H264 => 0,
            Codec::MotionResidual => 2,
            _ => 1,
        });
        let video = order
            .first()
            .filter(|(desc, _)| desc.codec == Codec::H264)
            .copied();
        let rest = &order[usize::from(video.is_some())..];
        if let Some((desc, _)) = rest.iter().find(|(desc, _)| desc.codec == Codec::H264) {
            // A second video-coded buffer: one decoder cannot take both.
            return Err(AssembleError::Codec {
                kind: desc.kind,
                source: CodecError::Stateful(desc.codec),
            });
        }
        let mut color_out = Vec::new();
        let (color_result, others) = std::thread::scope(|scope| {
            let color_job = video.map(|(desc, payload)| {
                let decoder = color
                    .take()
                    .filter(|d| d.codec() == desc.codec && desc.kind == BufferKind::Color);
                let out = &mut color_out;
                let job =
                    move || match decoder {
                        None => Err(CodecError::Stateful(desc.codec)),
                        Some(decoder) => decoder
                            .decode_color(&payload.data, meta.size, out)
                            .map_err(|source| CodecError::Stream {
                                codec: desc.codec,
                                source,
                            }),
                    };
                (desc.kind, scope.spawn(job))
            });
            let others = (|| {
                for (desc, payload) in rest {
                    let raw_len = desc.format.raw_len(meta.size);
                    let depth = (frame.depth.len() as u64 == meta.size.pixels())
                        .then_some(&frame.depth[..]);
                    let raw =
                        codec::decode_with(desc.codec, desc.format, &payload.data, raw_len, depth)
                            .map_err(|source| AssembleError::Codec {
                                kind: desc.kind,
                                source,
                            })?;
                    frame.set_buffer_bytes(desc.kind, desc.format, &raw)?;
                }
                Ok::<_, AssembleError>(())
            })();
            let color_result = color_job.map(|(kind, handle)| {
                match handle.join() {
                    Ok(result) => result.map_err(|source| AssembleError::Codec { kind, source }),
                    // A decoder's panic is a bug: it goes on as one.
                    Err(panic) => std::panic::resume_unwind(panic),
                }
            });
            (color_result, others)
        });
        // The colour's error first: a receiver asks for a keyframe on it.
        if let Some(result) = color_result {
            result?;
            frame.color = color_out;
        }
        others?;
        frame.validate(&limits)?;
        Ok(frame)
    }

    /// Total encoded payload bytes.
    pub fn payload_bytes(&self) -> u64 {
        self.payloads.iter().map(|p| p.data.len() as u64).sum()
    }
}

/// Encodes `frame` as a header plus payloads, one per entry of `buffers`
/// (which must include color, depth and motion), at zstd `level`, as the
/// first frame of a shot: see [`encode_frame_after`].
pub fn encode_frame(
    frame: &Frame,
    buffers: &[StreamBuffer],
    level: i32,
) -> Result<EncodedFrame, AssembleError> {
    encode_frame_after(frame, None, buffers, level)
}

/// [`encode_frame`] for a frame whose motion vectors point into a frame
/// seen as `previous` (the frame before it in the stream; ignored on a
/// cut). The quantised codecs use it: motion is sent as the residual over
/// the camera's motion between the two, and depth's error bound follows the
/// camera's step.
pub fn encode_frame_after(
    frame: &Frame,
    previous: Option<&FrameMeta>,
    buffers: &[StreamBuffer],
    level: i32,
) -> Result<EncodedFrame, AssembleError> {
    encode_frame_with(frame, previous, buffers, level, None)
}

/// [`encode_frame_after`], with the stream's colour encoder for a codec
/// whose state spans frames ([`codec::stream`]): it is given every frame
/// this returns, in order, and codes it on a thread of its own beside the
/// other buffers.
pub fn encode_frame_with(
    frame: &Frame,
    previous: Option<&FrameMeta>,
    buffers: &[StreamBuffer],
    level: i32,
    mut color: Option<&mut dyn ColorStreamEncoder>,
) -> Result<EncodedFrame, AssembleError> {
    frame.validate(&Limits::default())?;
    let previous = previous.filter(|_| !frame.meta.cut);
    let width = frame.meta.size.width;
    let quantizer = depth::Quantizer::for_frame(&frame.meta, previous);
    // The depth the receiver will have, which the motion predictor uses on
    // both sides.
    let lossy_depth = buffers
        .iter()
        .any(|b| b.kind == BufferKind::Depth && b.codec == Codec::QuantDepth);
    let codes = lossy_depth.then(|| quantizer.codes(&frame.depth));
    // Only a motion residual needs it: skip the round trip otherwise.
    let residual = buffers.iter().any(|b| b.codec == Codec::MotionResidual);
    let seen_depth: Cow<[f32]> = match &codes {
        Some(codes) if residual => Cow::Owned(quantizer.depths(codes)),
        _ => Cow::Borrowed(&frame.depth),
    };
    for b in buffers {
        b.validate()?;
    }
    // A video-coded colour buffer is encoded on a thread of its own, beside
    // the other buffers.
    let video = buffers.iter().position(|b| b.codec == Codec::H264);
    let encode = |b: &StreamBuffer| -> Result<Vec<u8>, AssembleError> {
        let coded = match b.codec {
            Codec::QuantDepth => match &codes {
                Some(codes) => depth::encode_codes(&quantizer, codes, width, level),
                None => depth::encode(&quantizer, &frame.depth, width, level),
            },
            Codec::MotionResidual => {
                let predictor =
                    motion::Predictor::new(&frame.meta, previous.unwrap_or(&frame.meta));
                motion::encode(&predictor, &frame.motion, &seen_depth, width, level)
            }
            // A second video-coded buffer: one encoder cannot take both.
            Codec::H264 => Err(CodecError::Stateful(b.codec)),
            other => {
                let raw = frame.buffer_bytes(b.kind, b.format)?;
                codec::encode_with_level(other, b.format, &raw, level)
            }
        };
        coded.map_err(|source| AssembleError::Codec {
            kind: b.kind,
            source,
        })
    };
    let results: Vec<Option<Result<Vec<u8>, AssembleError>>> = std::thread::scope(|scope| {
        let color_job = video.map(|i| {
            let b = &buffers[i];
            let encoder = color
                .take()
                .filter(|e| e.codec() == b.codec && b.kind == BufferKind::Color);
            let job =
                move || {
                    match encoder {
                        None => Err(CodecError::Stateful(b.codec)),
                        Some(encoder) => encoder
                            .encode_color(frame.meta.size, &frame.color)
                            .map_err(|source| CodecError::Stream {
                                codec: b.codec,
                                source,
                            }),
                    }
                    .map_err(|source| AssembleError::Codec {
                        kind: b.kind,
                        source,
                    })
                };
            scope.spawn(job)
        });
        let mut results: Vec<_> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| (Some(i) != video).then(|| encode(b)))
            .collect();
        if let (Some(i), Some(handle)) = (video, color_job) {
            results[i] = Some(match handle.join() {
                Ok(result) => result,
                // An encoder's panic is a bug: it goes on as one.
                Err(panic) => std::panic::resume_unwind(panic),
            });
        }
        results
    });
    let mut descs = Vec::with_capacity(buffers.len());
    let mut payloads = Vec::with_capacity(buffers.len());
    for (b, result) in buffers.iter().zip(results) {
        // The first failure in buffer order, as coded one after another
        // (every buffer has a result: its own or the colour thread's).
        let data = result.unwrap_or_else(|| {
            Err(AssembleError::Codec {
                kind: b.kind,
                source: CodecError::Stateful(b.codec),
            })
        })?;
        descs.push(BufferDesc {
            kind: b.kind,
            format: b.format,
            codec: b.codec,
            payload_len: data.len() as u64,
        });
        payloads.push(BufferPayload {
            frame_index: frame.meta.index,
            kind: b.kind,
            data,
        });
    }
    let header = FrameHeader {
        meta: frame.meta,
        buffers: descs,
        input: None,
    };
    Message::FrameHeader(header.clone()).validate(&Limits::default())?;
    Ok(EncodedFrame { header, payloads })
}

impl EncodedFrame {
    /// The bytes of the whole per-frame stream: header message, then payloads.
    pub fn to_stream_bytes(&self) -> Result<Vec<u8>, AssembleError> {
        let mut out = Vec::with_capacity(self.payload_bytes() as usize + 1024);
        wire::encode_into(&Message::FrameHeader(self.header.clone()), &mut out)?;
        for p in &self.payloads {
            out.extend_from_slice(&wire::payload_prefix(p.frame_index, p.kind, p.data.len())?);
            out.extend_from_slice(&p.data);
        }
        Ok(out)
    }
}

/// Sans-IO reassembly of one per-frame stream: feed it the stream's messages
/// in order; it checks each against the header and yields the
/// [`EncodedFrame`] when the last listed payload arrives.
#[derive(Debug, Default)]
pub struct FrameAssembler {
    header: Option<FrameHeader>,
    payloads: Vec<Option<BufferPayload>>,
    done: bool,
    failed: bool,
}

impl FrameAssembler {
    /// An assembler waiting for a frame header.
    pub fn new() -> Self {
        Self::default()
    }

    /// The header, once received.
    pub fn header(&self) -> Option<&FrameHeader> {
        self.header.as_ref()
    }

    /// Takes the next message of the stream. Returns the frame when it is
    /// complete. After any error the assembler stays failed
    /// ([`AssembleError::Poisoned`]): the stream must be dropped.
    pub fn push(&mut self, msg: Message) -> Result<Option<EncodedFrame>, AssembleError> {
        if self.failed {
            return Err(AssembleError::Poisoned);
        }
        let result = self.step(msg);
        if result.is_err() {
            self.failed = true;
        }
        result
    }

    fn step(&mut self, msg: Message) -> Result<Option<EncodedFrame>, AssembleError> {
        if self.done {
            return Err(AssembleError::Unexpected(msg.kind()));
        }
        match msg {
            Message::FrameHeader(h) if self.header.is_none() => {
                // Cheap, and keeps the assembler safe when fed by hand.
                Message::FrameHeader(h.clone()).validate(&Limits::default())?;
                self.payloads = vec![None; h.buffers.len()];
                self.header = Some(h);
                Ok(None)
            }
            Message::Payload(p) => {
                let header = self.header.as_ref().ok_or(AssembleError::HeaderMissing)?;
                if p.frame_index != header.meta.index {
                    return Err(AssembleError::FrameIndexMismatch {
                        expected: header.meta.index,
                        got: p.frame_index,
                    });
                }
                let slot = header
                    .buffers
                    .iter()
                    .position(|d| d.kind == p.kind)
                    .ok_or(AssembleError::UnlistedBuffer(p.kind))?;
                let expected = header.buffers[slot].payload_len;
                if p.data.len() as u64 != expected {
                    return Err(AssembleError::LengthMismatch {
                        kind: p.kind,
                        expected,
                        got: p.data.len() as u64,
                    });
                }
                if self.payloads[slot].is_some() {
                    return Err(AssembleError::DuplicatePayload(p.kind));
                }
                self.payloads[slot] = Some(p);
                if self.payloads.iter().all(Option::is_some) {
                    self.done = true;
                    let header = header.clone();
                    let payloads = std::mem::take(&mut self.payloads)
                        .into_iter()
                        .flatten()
                        .collect();
                    return Ok(Some(EncodedFrame { header, payloads }));
                }
                Ok(None)
            }
            other => Err(AssembleError::Unexpected(other.kind())),
        }
    }

    /// Call at the end of the stream: an error unless the frame completed.
    pub fn finish(&self) -> Result<(), AssembleError> {
        if self.done {
            return Ok(());
        }
        let missing = match &self.header {
            None => BufferKind::REQUIRED.to_vec(),
            Some(h) => h
                .buffers
                .iter()
                .zip(&self.payloads)
                .filter(|(_, p)| p.is_none())
                .map(|(d, _)| d.kind)
                .collect(),
        };
        Err(AssembleError::Incomplete { missing })
    }
}

/// Decodes a complete per-frame stream held in memory (a test helper and the
/// path for replaying captured streams): wire decoding, reassembly, codecs.
pub fn decode_frame_stream(bytes: &[u8], limits: &Limits) -> Result<Frame, AssembleError> {
    decode_frame_stream_with(bytes, limits, None)
}

/// [`decode_frame_stream`], with the stream's colour decoder
/// ([`EncodedFrame::decode_with`]).
pub fn decode_frame_stream_with(
    bytes: &[u8],
    limits: &Limits,
    color: Option<&mut dyn ColorStreamDecoder>,
) -> Result<Frame, AssembleError> {
    let mut decoder = Decoder::new(*limits);
    decoder.feed(bytes);
    let mut assembler = FrameAssembler::new();
    let mut complete = None;
    while let Some(msg) = decoder.next_message()? {
        if let Some(frame) = assembler.push(msg)? {
            complete = Some(frame);
        }
    }
    if !decoder.is_at_boundary() {
        return Err(WireError::Incomplete {
            needed: decoder.buffered(),
        }
        .into());
    }
    assembler.finish()?;
    match complete {
        Some(f) => f.decode_with(color),
        None => Err(AssembleError::Incomplete { missing: vec![] }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Codec;
    use crate::frame::tests::sample_frame;
    use crate::frame::{ExtraBuffer, PixelFormat};

    fn buffers(codec: Codec) -> Vec<StreamBuffer> {
        vec![
            StreamBuffer {
                kind: BufferKind::Color,
                format: PixelFormat::Rgba16Float,
                codec: Codec::Raw,
            },
            StreamBuffer {
                kind: BufferKind::Depth,
                format: PixelFormat::R32Float,
                codec,
            },
            StreamBuffer {
                kind: BufferKind::Motion,
                format: PixelFormat::Rg32Float,
                codec,
            },
        ]
    }

    #[test]
    fn frame_round_trips_through_a_stream() {
        let mut frame = sample_frame(42, 37, 21);
        frame.extras.push(ExtraBuffer {
            kind: BufferKind::Mask,
            data: (0..37 * 21).map(|i| (i % 256) as u8).collect(),
        });
        for codec in [Codec::Raw, Codec::Zstd] {
            let mut bufs = buffers(codec);
            bufs.push(StreamBuffer {
                kind: BufferKind::Mask,
                format: PixelFormat::R8Unorm,
                codec,
            });
            let enc = encode_frame(&frame, &bufs, 3).unwrap();
            let bytes = enc.to_stream_bytes().unwrap();
            let back = decode_frame_stream(&bytes, &Limits::default()).unwrap();
            assert_eq!(back, frame);
            // Byte-by-byte feeding gives the same messages.
            let mut d = Decoder::new(Limits::default());
            let mut a = FrameAssembler::new();
            let mut got = None;
            for b in &bytes {
                d.feed(std::slice::from_ref(b));
                while let Some(m) = d.next_message().unwrap() {
                    got = a.push(m).unwrap().or(got);
                }
            }
            assert_eq!(got.unwrap(), enc);
        }
    }

    /// The compact set (quantised depth, motion over the camera) through a
    /// whole stream: depth within its relative bound, sky exact, every
    /// motion vector within half a quantum, whether or not the previous
    /// camera is known, and a motion residual without its depth refused.
    #[test]
    fn the_compact_set_round_trips_within_its_bounds() {
        let mut frame = sample_frame(9, 48, 20);
        let mut previous = frame.meta;
        previous.camera.pose.position.x -= 0.05;
        previous.camera.pose.rotation = glam::DQuat::from_rotation_y(0.29);
        // Static motion, from the camera model, except one moving block.
        for y in 0..20u32 {
            for x in 0..48u32 {
                let i = frame.index(x, y);
                let m =
                    motion::Predictor::new(&frame.meta, &previous).predict(x, y, frame.depth[i]);
                let block = if (10..20).contains(&x) { 1.25 } else { 0.0 };
                frame.motion[i] = [m[0] as f32 + block, m[1] as f32];
            }
        }
        let buffers = StreamBuffer::compact_set(Codec::Raw);
        for prev in [Some(&previous), None] {
            let enc = encode_frame_after(&frame, prev, &buffers, 1).unwrap();
            let bytes = enc.to_stream_bytes().unwrap();
            let back = decode_frame_stream(&bytes, &Limits::default()).unwrap();
            for (a, b) in frame.depth.iter().zip(&back.depth) {
                if a.is_finite() {
                    assert!((b / a - 1.0).abs() <= 7e-5, "{a} vs {b}");
                } else {
                    assert_eq!(a, b);
                }
            }
            for (a, b) in frame.motion.iter().zip(&back.motion) {
                for c in 0..2 {
                    assert!(
                        f64::from((a[c] - b[c]).abs()) <= motion::QUANTUM / 2.0 + 1e-4,
                        "{a:?} vs {b:?}"
                    );
                }
            }
            assert_eq!(back.color, frame.color);
        }
        let enc = encode_frame_after(&frame, Some(&previous), &buffers, 1).unwrap();
        let motion_payload = &enc.payloads[2].data;
        assert!(matches!(
            codec::decode(
                Codec::MotionResidual,
                crate::frame::PixelFormat::Rg32Float,
                motion_payload,
                48 * 20 * 8
            ),
            Err(CodecError::NeedsDepth)
        ));
    }

    /// A stand-in video coder for the wiring (the real one is crate
    /// `video`): the payload is a count, then the colour's f16 bytes; the
    /// decoder refuses a count that is not the next.
    #[derive(Default)]
    struct Counting(u8);

    impl ColorStreamEncoder for Counting {
        fn codec(&self) -> Codec {
            Codec::H264
        }
        fn encode_color(
            &mut self,
            _: crate::FrameSize,
            color: &[[half::f16; 4]],
        ) -> Result<Vec<u8>, codec::stream::StreamError> {
            self.0 += 1;
            let bytes = color.iter().flatten().flat_map(|c| c.to_le_bytes());
            Ok(std::iter::once(self.0).chain(bytes).collect())
        }
    }

    impl ColorStreamDecoder for Counting {
        fn codec(&self) -> Codec {
            Codec::H264
        }
        fn decode_color(
            &mut self,
            payload: &[u8],
            _: crate::FrameSize,
            out: &mut Vec<[half::f16; 4]>,
        ) -> Result<(), codec::stream::StreamError> {
            self.0 += 1;
            if payload.first() != Some(&self.0) {
                return Err("out of sequence".into());
            }
            let values: Vec<half::f16> = payload[1..]
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes([b[0], b[1]]))
                .collect();
            out.clear();
            out.extend(values.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]));
            Ok(())
        }
    }

    /// Video-coded colour goes through the stream's coders, in order, and
    /// the decoder sees it before the other buffers; without a coder it is
    /// a typed error, and so is the coder's refusal.
    #[test]
    fn video_coded_colour_goes_through_the_streams_coders() -> Result<(), AssembleError> {
        let buffers = StreamBuffer::compact_set(Codec::H264);
        let frames: Vec<Frame> = (0..3).map(|i| sample_frame(i, 16, 8)).collect();
        let mut encoder = Counting::default();
        let encoded = frames
            .iter()
            .map(|f| encode_frame_with(f, None, &buffers, 1, Some(&mut encoder)))
            .collect::<Result<Vec<EncodedFrame>, _>>()?;
        assert!(matches!(
            encode_frame(&frames[0], &buffers, 1),
            Err(AssembleError::Codec {
                kind: BufferKind::Color,
                source: CodecError::Stateful(Codec::H264)
            })
        ));
        assert!(matches!(
            encoded[0].decode(),
            Err(AssembleError::Codec {
                source: CodecError::Stateful(Codec::H264),
                ..
            })
        ));
        let mut decoder = Counting::default();
        let back = encoded[0].decode_with(Some(&mut decoder))?;
        assert_eq!(back.color, frames[0].color);
        // Frame 1 lost: frame 2 is refused by the coder, as a codec error
        // of the colour buffer.
        assert!(matches!(
            encoded[2].decode_with(Some(&mut decoder)),
            Err(AssembleError::Codec {
                kind: BufferKind::Color,
                source: CodecError::Stream {
                    codec: Codec::H264,
                    ..
                }
            })
        ));
        // A damaged depth payload: the colour decoder (on its own thread)
        // is fed all the same, so the next frame follows in sequence, and
        // the depth's error is returned.
        let mut decoder = Counting::default();
        let mut damaged = encoded[0].clone();
        damaged.payloads[1].data.fill(0xAA);
        assert!(matches!(
            damaged.decode_with(Some(&mut decoder)),
            Err(AssembleError::Codec {
                kind: BufferKind::Depth,
                ..
            })
        ));
        assert_eq!(
            encoded[1].decode_with(Some(&mut decoder))?.color,
            frames[1].color
        );
        // Both failing (the decoder expects frame 2): the colour's error.
        assert!(matches!(
            damaged.decode_with(Some(&mut decoder)),
            Err(AssembleError::Codec {
                kind: BufferKind::Color,
                ..
            })
        ));
        // Colour is the only buffer the codec suits.
        let mut wrong = buffers.to_vec();
        wrong[1].codec = Codec::H264;
        assert!(encode_frame_with(&frames[0], None, &wrong, 1, Some(&mut encoder)).is_err());
        Ok(())
    }

    #[test]
    fn payloads_may_arrive_in_any_order_but_must_match_the_header() {
        let frame = sample_frame(7, 8, 8);
        let enc = encode_frame(&frame, &buffers(Codec::Zstd), 1).unwrap();
        let started = || {
            let mut a = FrameAssembler::new();
            a.push(Message::FrameHeader(enc.header.clone())).unwrap();
            a
        };
        let payload = |i: usize| Message::Payload(enc.payloads[i].clone());
        let mut a = FrameAssembler::new();
        assert!(matches!(
            a.push(payload(0)),
            Err(AssembleError::HeaderMissing)
        ));
        // Any error poisons the stream.
        assert!(matches!(
            a.push(Message::FrameHeader(enc.header.clone())),
            Err(AssembleError::Poisoned)
        ));

        let mut a = started();
        assert!(a.push(payload(2)).unwrap().is_none());
        assert!(matches!(
            a.push(payload(2)),
            Err(AssembleError::DuplicatePayload(BufferKind::Motion))
        ));

        let mut wrong = enc.payloads[0].clone();
        wrong.frame_index = 8;
        assert!(matches!(
            started().push(Message::Payload(wrong)),
            Err(AssembleError::FrameIndexMismatch {
                expected: 7,
                got: 8
            })
        ));
        let mut short = enc.payloads[0].clone();
        short.data.pop();
        assert!(matches!(
            started().push(Message::Payload(short)),
            Err(AssembleError::LengthMismatch { .. })
        ));
        let unlisted = BufferPayload {
            frame_index: 7,
            kind: BufferKind::Normal,
            data: vec![],
        };
        assert!(matches!(
            started().push(Message::Payload(unlisted)),
            Err(AssembleError::UnlistedBuffer(BufferKind::Normal))
        ));
        let mut second_header = started();
        assert!(matches!(
            second_header.push(Message::FrameHeader(enc.header.clone())),
            Err(AssembleError::Unexpected(MessageKind::FrameHeader))
        ));

        // Out of order completes; incomplete before that.
        let mut a = started();
        a.push(payload(2)).unwrap();
        assert!(
            matches!(a.finish(), Err(AssembleError::Incomplete { ref missing }) if missing.len() == 2)
        );
        a.push(payload(1)).unwrap();
        let done = a.push(payload(0)).unwrap().unwrap();
        assert_eq!(done.decode().unwrap(), frame);
        a.finish().unwrap();
        assert!(matches!(
            a.push(payload(0)),
            Err(AssembleError::Unexpected(MessageKind::Payload))
        ));
    }

    #[test]
    fn hand_built_encoded_frames_are_checked_too() {
        let frame = sample_frame(3, 8, 8);
        let enc = encode_frame(&frame, &buffers(Codec::Raw), 1).unwrap();
        let mut missing = enc.clone();
        missing.payloads.pop();
        assert!(matches!(
            missing.decode(),
            Err(AssembleError::Incomplete { .. })
        ));
        let mut swapped = enc.clone();
        swapped.payloads.swap(1, 2);
        assert!(swapped.decode().is_err());
        let mut huge = enc.clone();
        huge.header.meta.size.width = u32::MAX;
        assert!(matches!(huge.decode(), Err(AssembleError::Invalid(_))));
        let mut nan = enc;
        nan.header.meta.camera.pose.position.x = f64::NAN;
        assert!(matches!(nan.decode(), Err(AssembleError::Invalid(_))));
    }

    #[test]
    fn corrupt_zstd_payload_is_a_codec_error() {
        let frame = sample_frame(1, 16, 16);
        let mut enc = encode_frame(&frame, &buffers(Codec::Zstd), 1).unwrap();
        let d = &mut enc.payloads[1].data;
        let mid = d.len() / 2;
        d[mid] ^= 0xff;
        d[mid + 1] ^= 0x55;
        // The zstd content checksum catches it.
        assert!(matches!(
            enc.decode(),
            Err(AssembleError::Codec {
                kind: BufferKind::Depth,
                ..
            })
        ));
    }

    #[test]
    fn truncated_stream_is_incomplete() {
        let frame = sample_frame(1, 16, 16);
        let bytes = encode_frame(&frame, &buffers(Codec::Raw), 1)
            .unwrap()
            .to_stream_bytes()
            .unwrap();
        for cut in [0, 5, 100, bytes.len() - 1] {
            assert!(
                decode_frame_stream(&bytes[..cut], &Limits::default()).is_err(),
                "{cut}"
            );
        }
    }
}
