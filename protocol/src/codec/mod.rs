//! Buffer codecs (DESIGN §7): raw; lossless zstd; and for a stream at real
//! bitrates (issue 19), depth quantised with a stated error bound
//! ([`depth`]) and motion as a residual over the camera ([`motion`]).
//!
//! Colour at real bitrates goes through a video codec ([`Codec::H264`]),
//! whose state spans frames: protocol only names it and hands its payloads
//! to the stream's own coder ([`stream`]), which lives outside this crate
//! (crate `video`).
//!
//! [`Codec::Zstd`] first splits the pixels into byte planes (byte 0 of every
//! channel value, then byte 1, …): the sign/exponent bytes of neighbouring
//! floats are nearly equal, so the planes compress far better than the
//! interleaved values do. Frames carry zstd's content checksum, so corruption
//! is an error rather than wrong pixels. Decoding never allocates more than the raw size the
//! frame header implies, which the caller has already validated.

use serde::{Deserialize, Serialize};

use crate::{BufferKind, PixelFormat};

pub mod depth;
pub mod motion;
mod planar;
pub mod stream;

/// zstd level used by [`encode`]: level 1 is the fastest that still compresses
/// depth and motion well; pass another to [`encode_with_level`].
pub const DEFAULT_ZSTD_LEVEL: i32 = 1;

/// How a buffer's bytes are compressed on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Codec {
    /// Uncompressed little-endian pixels.
    Raw,
    /// Byte-plane shuffle, then zstd (lossless).
    Zstd,
    /// Depth quantised with a bounded error ([`depth`]): relative error
    /// ≤ 6·10⁻⁵, reprojection error ≤ 0.05 px; sky and NaN exact.
    QuantDepth,
    /// Motion minus the camera-induced motion, quantised to 1/128 px
    /// ([`motion`]); decoding needs the frame's depth.
    MotionResidual,
    /// Colour as one H.264 access unit a frame, coded and decoded by the
    /// stream's own coder ([`stream`]), in order, from a keyframe on.
    H264,
}

/// A buffer that cannot be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// The raw input length is not a whole number of channel values.
    #[error("raw buffer of {len} bytes is not a multiple of the {unit}-byte channel size")]
    Misaligned {
        /// Input length.
        len: usize,
        /// Channel size.
        unit: usize,
    },
    /// zstd refused the data (corrupt, or larger than the expected size).
    #[error("zstd: {0}")]
    Zstd(#[source] std::io::Error),
    /// The decoded size differs from what the header announced.
    #[error("decoded {got} bytes, expected {expected}")]
    WrongLength {
        /// Bytes produced.
        got: u64,
        /// Bytes announced.
        expected: u64,
    },
    /// A lossy codec's parameters or header are unusable.
    #[error("bad {0}")]
    BadParameters(&'static str),
    /// The codec needs the frame's depth (it is decoded from the frame).
    #[error("motion residuals decode against the frame's depth, which was not given")]
    NeedsDepth,
    /// The codec cannot carry this buffer.
    #[error("{codec:?} cannot carry a {kind:?} buffer as {format:?}")]
    Unsuited {
        /// The codec.
        codec: Codec,
        /// The buffer.
        kind: BufferKind,
        /// Its format.
        format: PixelFormat,
    },
    /// The codec's state spans frames, and the stream's coder for it was not
    /// given ([`stream`]).
    #[error("{0:?} is coded by the stream's own coder, which was not given")]
    Stateful(Codec),
    /// The stream's coder refused this frame (a video payload that is
    /// corrupt, or predicted from a frame the receiver lost).
    #[error("{codec:?}: {source}")]
    Stream {
        /// The codec.
        codec: Codec,
        /// What the coder reported.
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The encoded payload is longer than a codec can produce for the size.
    #[error("encoded payload of {len} bytes is outside {min}..={max} for this codec")]
    EncodedLength {
        /// Payload length.
        len: u64,
        /// Smallest possible.
        min: u64,
        /// Largest possible.
        max: u64,
    },
}

impl Codec {
    /// Every codec, in declaration order.
    pub const ALL: [Codec; 5] = [
        Codec::Raw,
        Codec::Zstd,
        Codec::QuantDepth,
        Codec::MotionResidual,
        Codec::H264,
    ];

    /// The range of encoded lengths this codec can produce for `raw` bytes of
    /// `format` pixels. Used to reject inconsistent headers before any
    /// allocation.
    pub fn encoded_len_range(self, format: PixelFormat, raw: u64) -> (u64, u64) {
        match self {
            Codec::Raw => (raw, raw),
            Codec::Zstd => (1, zstd_compress_bound(raw)),
            // One code a pixel.
            Codec::QuantDepth => {
                let codes = raw / u64::from(format.bytes_per_pixel().max(1));
                (
                    depth::HEADER as u64 + 1,
                    depth::HEADER as u64 + planar::max_packed_len(codes),
                )
            }
            // Two codes a pixel.
            Codec::MotionResidual => {
                let codes = raw / u64::from(format.bytes_per_pixel().max(1)) * 2;
                (
                    motion::HEADER as u64 + 1,
                    motion::HEADER as u64 + planar::max_packed_len(codes),
                )
            }
            // A video access unit is far smaller than the f16 frame: even
            // uncompressed (I_PCM) macroblocks at 10 bits and 4:4:4 take
            // 3.75 bytes a pixel against raw RGB's 6; the margin holds
            // the parameter sets and the coder's own header.
            Codec::H264 => (1, raw.saturating_add(stream::MAX_OVERHEAD)),
        }
    }

    /// Whether this codec can carry buffer `kind` as `format`: the lossless
    /// ones carry anything, the quantised ones only what they model.
    pub fn suits(self, kind: BufferKind, format: PixelFormat) -> bool {
        match self {
            Codec::Raw | Codec::Zstd => true,
            Codec::QuantDepth => kind == BufferKind::Depth && format == PixelFormat::R32Float,
            Codec::MotionResidual => {
                kind == BufferKind::Motion
                    && matches!(format, PixelFormat::Rg32Float | PixelFormat::Rg16Float)
            }
            // Alpha is not carried.
            Codec::H264 => kind == BufferKind::Color && format == PixelFormat::Rgb16Float,
        }
    }

    /// True for codecs whose output equals their input.
    pub fn is_lossless(self) -> bool {
        matches!(self, Codec::Raw | Codec::Zstd)
    }
}

/// The most bytes of header a codec puts before its data.
pub const MAX_HEADER: u64 = motion::HEADER as u64;

/// `ZSTD_COMPRESSBOUND` from zstd.h, in `u64`: the largest output zstd
/// produces for `src` input bytes (one frame).
pub fn zstd_compress_bound(src: u64) -> u64 {
    const KB128: u64 = 128 << 10;
    let margin = if src < KB128 { (KB128 - src) >> 11 } else { 0 };
    src.saturating_add(src >> 8).saturating_add(margin)
}

/// Encodes `raw` pixels of `format` with `codec` at the default zstd level.
pub fn encode(codec: Codec, format: PixelFormat, raw: &[u8]) -> Result<Vec<u8>, CodecError> {
    encode_with_level(codec, format, raw, DEFAULT_ZSTD_LEVEL)
}

/// Encodes `raw` pixels of `format` with `codec`; `level` is the zstd level.
pub fn encode_with_level(
    codec: Codec,
    format: PixelFormat,
    raw: &[u8],
    level: i32,
) -> Result<Vec<u8>, CodecError> {
    match codec {
        Codec::Raw => Ok(raw.to_vec()),
        Codec::Zstd => zstd_pack(raw, format.channel_bytes() as usize, level),
        // Without a frame around it, depth gets the relative scale.
        Codec::QuantDepth => {
            check_suits(codec, BufferKind::Depth, format)?;
            let values = f32_values(raw)?;
            depth::encode(
                &depth::Quantizer::relative(),
                &values,
                plane_width(values.len()),
                level,
            )
        }
        Codec::MotionResidual => Err(CodecError::NeedsDepth),
        Codec::H264 => Err(CodecError::Stateful(codec)),
    }
}

/// Byte-plane shuffle of `unit`-byte values, then zstd at `level` with a
/// content checksum.
fn zstd_pack(raw: &[u8], unit: usize, level: i32) -> Result<Vec<u8>, CodecError> {
    zstd_compress(&shuffle(raw, unit)?, level)
}

/// zstd at `level` with a content checksum: corruption becomes an error
/// instead of wrong pixels.
pub(crate) fn zstd_compress(bytes: &[u8], level: i32) -> Result<Vec<u8>, CodecError> {
    let mut z = zstd::bulk::Compressor::new(level).map_err(CodecError::Zstd)?;
    z.include_checksum(true).map_err(CodecError::Zstd)?;
    z.compress(bytes).map_err(CodecError::Zstd)
}

/// Exactly `expected` bytes out of a zstd frame, or an error.
pub(crate) fn zstd_decompress(encoded: &[u8], expected: usize) -> Result<Vec<u8>, CodecError> {
    let bytes = zstd::bulk::decompress(encoded, expected).map_err(CodecError::Zstd)?;
    if bytes.len() != expected {
        return Err(CodecError::WrongLength {
            got: bytes.len() as u64,
            expected: expected as u64,
        });
    }
    Ok(bytes)
}

/// Inverse of [`zstd_pack`]: exactly `expected` bytes, or an error.
fn zstd_unpack(encoded: &[u8], expected: usize, unit: usize) -> Result<Vec<u8>, CodecError> {
    unshuffle(&zstd_decompress(encoded, expected)?, unit)
}

fn check_suits(codec: Codec, kind: BufferKind, format: PixelFormat) -> Result<(), CodecError> {
    if codec.suits(kind, format) {
        Ok(())
    } else {
        Err(CodecError::Unsuited {
            codec,
            kind,
            format,
        })
    }
}

/// `v` rounded half away from zero to an `i32` (saturating; NaN gives 0),
/// by a truncating cast rather than a call to `round`.
pub(crate) fn round_i32(v: f64) -> i32 {
    (v + 0.5f64.copysign(v)) as i32
}

/// A plane of `n` values with no width known: one row.
fn plane_width(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX).max(1)
}

fn f32_values(raw: &[u8]) -> Result<Vec<f32>, CodecError> {
    if raw.len() % 4 != 0 {
        return Err(CodecError::Misaligned {
            len: raw.len(),
            unit: 4,
        });
    }
    Ok(raw
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect())
}

/// Decodes an `encoded` payload of `format` pixels with `codec`, producing
/// exactly `expected_len` bytes or an error. `expected_len` must already be
/// validated against the limits: it is the only size allocated.
/// [`Codec::MotionResidual`] needs the frame's depth: see [`decode_with`].
pub fn decode(
    codec: Codec,
    format: PixelFormat,
    encoded: &[u8],
    expected_len: u64,
) -> Result<Vec<u8>, CodecError> {
    decode_with(codec, format, encoded, expected_len, None)
}

/// [`decode`], with the frame's decoded `depth` for the codecs that predict
/// from it.
pub fn decode_with(
    codec: Codec,
    format: PixelFormat,
    encoded: &[u8],
    expected_len: u64,
    depth: Option<&[f32]>,
) -> Result<Vec<u8>, CodecError> {
    let (min, max) = codec.encoded_len_range(format, expected_len);
    let len = encoded.len() as u64;
    if len < min || len > max {
        return Err(CodecError::EncodedLength { len, min, max });
    }
    let unit = format.channel_bytes() as usize;
    let expected = usize::try_from(expected_len).map_err(|_| CodecError::WrongLength {
        got: 0,
        expected: expected_len,
    })?;
    if expected % unit != 0 {
        return Err(CodecError::Misaligned {
            len: expected,
            unit,
        });
    }
    let bpp = format.bytes_per_pixel().max(1) as usize;
    if !codec.is_lossless() && expected % bpp != 0 {
        return Err(CodecError::Misaligned {
            len: expected,
            unit: bpp,
        });
    }
    let pixels = expected / bpp;
    match codec {
        Codec::Raw => Ok(encoded.to_vec()),
        Codec::Zstd => zstd_unpack(encoded, expected, unit),
        Codec::QuantDepth => {
            check_suits(codec, BufferKind::Depth, format)?;
            let (values, _) = depth::decode(encoded, pixels)?;
            Ok(values.iter().flat_map(|v| v.to_le_bytes()).collect())
        }
        Codec::MotionResidual => {
            check_suits(codec, BufferKind::Motion, format)?;
            let depth = depth.ok_or(CodecError::NeedsDepth)?;
            if depth.len() != pixels {
                return Err(CodecError::WrongLength {
                    got: depth.len() as u64,
                    expected: pixels as u64,
                });
            }
            let motion = motion::decode(encoded, depth)?;
            Ok(match format {
                PixelFormat::Rg16Float => motion
                    .iter()
                    .flatten()
                    .flat_map(|v| half::f16::from_f32(*v).to_le_bytes())
                    .collect(),
                _ => motion
                    .iter()
                    .flatten()
                    .flat_map(|v| v.to_le_bytes())
                    .collect(),
            })
        }
        Codec::H264 => Err(CodecError::Stateful(codec)),
    }
}

/// Splits interleaved `unit`-byte values into byte planes.
fn shuffle(raw: &[u8], unit: usize) -> Result<Vec<u8>, CodecError> {
    if raw.len() % unit != 0 {
        return Err(CodecError::Misaligned {
            len: raw.len(),
            unit,
        });
    }
    if unit == 1 {
        return Ok(raw.to_vec());
    }
    let n = raw.len() / unit;
    let mut out = vec![0u8; raw.len()];
    for (i, value) in raw.chunks_exact(unit).enumerate() {
        for (b, &byte) in value.iter().enumerate() {
            out[b * n + i] = byte;
        }
    }
    Ok(out)
}

/// Inverse of [`shuffle`].
fn unshuffle(planes: &[u8], unit: usize) -> Result<Vec<u8>, CodecError> {
    if planes.len() % unit != 0 {
        return Err(CodecError::Misaligned {
            len: planes.len(),
            unit,
        });
    }
    if unit == 1 {
        return Ok(planes.to_vec());
    }
    let n = planes.len() / unit;
    let mut out = vec![0u8; planes.len()];
    for (i, value) in out.chunks_exact_mut(unit).enumerate() {
        for (b, byte) in value.iter_mut().enumerate() {
            *byte = planes[b * n + i];
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn depth_like(n: usize) -> Vec<u8> {
        (0..n)
            .map(|i| 10.0f32 + (i % 97) as f32 * 0.01 + (i / 97) as f32 * 0.003)
            .flat_map(f32::to_le_bytes)
            .collect()
    }

    #[test]
    fn zstd_is_lossless_and_shrinks_smooth_depth() {
        let raw = depth_like(64 * 64);
        let enc = encode(Codec::Zstd, PixelFormat::R32Float, &raw).unwrap();
        assert!(enc.len() * 2 < raw.len(), "{} vs {}", enc.len(), raw.len());
        let dec = decode(Codec::Zstd, PixelFormat::R32Float, &enc, raw.len() as u64).unwrap();
        assert_eq!(dec, raw);
    }

    #[test]
    fn decode_refuses_sizes_that_disagree_with_the_header() {
        let raw = depth_like(1000);
        let enc = encode(Codec::Zstd, PixelFormat::R32Float, &raw).unwrap();
        // Announcing fewer bytes than the data holds: zstd stops at the cap.
        assert!(decode(Codec::Zstd, PixelFormat::R32Float, &enc, 400).is_err());
        // Announcing more: the output is short.
        assert!(matches!(
            decode(Codec::Zstd, PixelFormat::R32Float, &enc, 8000),
            Err(CodecError::WrongLength { .. })
        ));
        // Raw payloads must match exactly.
        assert!(matches!(
            decode(Codec::Raw, PixelFormat::R32Float, &raw, 3996),
            Err(CodecError::EncodedLength { .. })
        ));
        // A payload far larger than the compress bound is refused up front.
        let junk = vec![0u8; 1000];
        assert!(matches!(
            decode(Codec::Zstd, PixelFormat::R32Float, &junk, 8),
            Err(CodecError::EncodedLength { .. })
        ));
        // Garbage is an error, not a panic.
        assert!(decode(Codec::Zstd, PixelFormat::R32Float, &junk[..100], 4000).is_err());
    }

    #[test]
    fn compress_bound_matches_zstd() {
        for n in [0u64, 1, 100, 131_071, 131_072, 1 << 20, 8192 * 8192 * 8] {
            assert_eq!(
                zstd_compress_bound(n),
                zstd::zstd_safe::compress_bound(n as usize) as u64,
                "{n}"
            );
        }
    }

    proptest! {
        #[test]
        fn round_trip_any_bytes(values in proptest::collection::vec(any::<u32>(), 0..512), level in 1i32..5) {
            let raw: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            for (codec, format) in [(Codec::Raw, PixelFormat::R32Float), (Codec::Zstd, PixelFormat::R32Float),
                                    (Codec::Zstd, PixelFormat::Rg16Float), (Codec::Zstd, PixelFormat::R8Unorm)] {
                let enc = encode_with_level(codec, format, &raw, level).unwrap();
                let dec = decode(codec, format, &enc, raw.len() as u64).unwrap();
                prop_assert_eq!(&dec, &raw);
            }
        }
    }
}
