//! Frame metadata, buffer descriptors and decoded frames (DESIGN §3).

use std::time::Duration;

use half::f16;
use serde::{Deserialize, Serialize};

use crate::{Camera, Codec, Limits, ValidationError};

/// Image dimensions in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct FrameSize {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

impl FrameSize {
    /// A size of `width × height` pixels.
    pub const fn new(width: u32, height: u32) -> Self {
        Self { width, height }
    }

    /// Number of pixels, computed without overflow.
    pub fn pixels(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height)
    }

    /// The size as floats, for the [`Camera`] helpers.
    pub fn as_f64(&self) -> (f64, f64) {
        crate::camera::size_f(self.width, self.height)
    }
}

/// A size that `WIDTHxHEIGHT` text does not give.
#[derive(Debug, thiserror::Error)]
pub enum ParseSizeError {
    /// No `x` between the two numbers.
    #[error("expected WIDTHxHEIGHT, e.g. 1280x720")]
    Format,
    /// A side that is not a number.
    #[error("{side}: {source}")]
    Number {
        /// `width` or `height`.
        side: &'static str,
        /// Why.
        source: std::num::ParseIntError,
    },
    /// Sides outside the default [`Limits`].
    #[error(transparent)]
    Invalid(#[from] ValidationError),
}

impl std::str::FromStr for FrameSize {
    type Err = ParseSizeError;

    /// `WIDTHxHEIGHT` (e.g. `1280x720`), within the default [`Limits`].
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let (w, h) = s.split_once('x').ok_or(ParseSizeError::Format)?;
        let side = |side, v: &str| {
            v.parse::<u32>()
                .map_err(|source| ParseSizeError::Number { side, source })
        };
        let (w, h) = (side("width", w)?, side("height", h)?);
        Limits::default().check_size(w, h)?;
        Ok(FrameSize::new(w, h))
    }
}

/// Everything about a rendered frame except its pixels.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameMeta {
    /// Frame number in the stream, strictly increasing.
    pub index: u64,
    /// Simulation time (seconds) of the state the frame shows. Generated
    /// frames carry `t + α·Δ`.
    pub time: f64,
    /// The camera that rendered the frame, including its window.
    pub camera: Camera,
    /// Size of the rendered image (of the whole window, not the crop).
    pub size: FrameSize,
    /// Host processing time (render + encode) as a duration, as Sunshine
    /// reports it, so the client needs no synchronised clock.
    pub host_processing: Duration,
    /// True when this frame starts a new shot: there is no continuity with the
    /// previous frame, so history must be dropped and its motion vectors do
    /// not point into the previous frame.
    pub cut: bool,
}

/// Largest |simulation time| of a frame, seconds (some 31 years): an `f64`
/// time keeps sub-microsecond steps up to here.
pub const MAX_TIME: f64 = 1e9;

/// Longest host processing time a frame may report (a day: an offline
/// render's time, with room for the encode added to it without overflow).
pub const MAX_HOST_PROCESSING: Duration = Duration::from_secs(86_400);

impl FrameMeta {
    /// Checks the camera, the time, the host processing time and the size
    /// against `limits`.
    pub fn validate(&self, limits: &Limits) -> Result<(), ValidationError> {
        if !self.time.is_finite() {
            return Err(ValidationError::NonFinite("frame time"));
        }
        if self.time.abs() > MAX_TIME {
            return Err(ValidationError::OutOfRange("frame time"));
        }
        if self.host_processing > MAX_HOST_PROCESSING {
            return Err(ValidationError::OutOfRange("host processing time"));
        }
        limits.check_size(self.size.width, self.size.height)?;
        self.camera.validate()
    }
}

/// What a buffer holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum BufferKind {
    /// Linear HDR RGB (required).
    Color,
    /// Linear view depth, `+inf` for sky (required).
    Depth,
    /// Motion vectors current → previous, in pixels (required).
    Motion,
    /// Optional extra: world-space shading normal.
    Normal,
    /// Optional extra: surface albedo.
    Albedo,
    /// Optional extra: an 8-bit mask (e.g. dynamic objects).
    Mask,
}

impl BufferKind {
    /// Every kind, required ones first.
    pub const ALL: [BufferKind; 6] = [
        BufferKind::Color,
        BufferKind::Depth,
        BufferKind::Motion,
        BufferKind::Normal,
        BufferKind::Albedo,
        BufferKind::Mask,
    ];

    /// The kinds every frame carries.
    pub const REQUIRED: [BufferKind; 3] =
        [BufferKind::Color, BufferKind::Depth, BufferKind::Motion];

    /// The pixel formats a buffer of this kind may use.
    pub fn allowed_formats(self) -> &'static [PixelFormat] {
        use PixelFormat::*;
        match self {
            BufferKind::Color | BufferKind::Albedo => &[Rgb16Float, Rgba16Float],
            BufferKind::Depth => &[R32Float],
            BufferKind::Motion => &[Rg32Float, Rg16Float],
            BufferKind::Normal => &[Rgb16Float],
            BufferKind::Mask => &[R8Unorm],
        }
    }

    /// Whether every frame must carry this kind.
    pub fn is_required(self) -> bool {
        Self::REQUIRED.contains(&self)
    }

    /// The format a frame holds this kind in after decoding.
    pub fn canonical_format(self) -> PixelFormat {
        match self {
            BufferKind::Color | BufferKind::Albedo => PixelFormat::Rgba16Float,
            BufferKind::Depth => PixelFormat::R32Float,
            BufferKind::Motion => PixelFormat::Rg32Float,
            BufferKind::Normal => PixelFormat::Rgb16Float,
            BufferKind::Mask => PixelFormat::R8Unorm,
        }
    }
}

/// How pixels are laid out in a buffer: interleaved channels, little-endian.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum PixelFormat {
    /// 4 × f16.
    Rgba16Float,
    /// 3 × f16.
    Rgb16Float,
    /// 2 × f16.
    Rg16Float,
    /// 1 × f32.
    R32Float,
    /// 2 × f32.
    Rg32Float,
    /// 1 × u8.
    R8Unorm,
}

impl PixelFormat {
    /// Every format.
    pub const ALL: [PixelFormat; 6] = [
        PixelFormat::Rgba16Float,
        PixelFormat::Rgb16Float,
        PixelFormat::Rg16Float,
        PixelFormat::R32Float,
        PixelFormat::Rg32Float,
        PixelFormat::R8Unorm,
    ];

    /// Channels per pixel.
    pub fn channels(self) -> u32 {
        match self {
            PixelFormat::Rgba16Float => 4,
            PixelFormat::Rgb16Float => 3,
            PixelFormat::Rg16Float | PixelFormat::Rg32Float => 2,
            PixelFormat::R32Float | PixelFormat::R8Unorm => 1,
        }
    }

    /// Bytes per channel.
    pub fn channel_bytes(self) -> u32 {
        match self {
            PixelFormat::Rgba16Float | PixelFormat::Rgb16Float | PixelFormat::Rg16Float => 2,
            PixelFormat::R32Float | PixelFormat::Rg32Float => 4,
            PixelFormat::R8Unorm => 1,
        }
    }

    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> u32 {
        self.channels() * self.channel_bytes()
    }

    /// Size of an uncompressed `size` image in this format.
    pub fn raw_len(self, size: FrameSize) -> u64 {
        size.pixels()
            .saturating_mul(u64::from(self.bytes_per_pixel()))
    }
}

/// Describes one buffer of a frame on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BufferDesc {
    /// What the buffer holds.
    pub kind: BufferKind,
    /// Pixel layout before the codec.
    pub format: PixelFormat,
    /// How the bytes are compressed.
    pub codec: Codec,
    /// Length of the encoded payload in bytes.
    pub payload_len: u64,
}

impl BufferDesc {
    /// Checks that the format suits the kind and that the payload length is
    /// consistent with the size, format and codec, and within `limits`.
    pub fn validate(&self, size: FrameSize, limits: &Limits) -> Result<(), ValidationError> {
        if !self.kind.allowed_formats().contains(&self.format) {
            return Err(ValidationError::FormatNotAllowed {
                kind: self.kind,
                format: self.format,
            });
        }
        if !self.codec.suits(self.kind, self.format) {
            return Err(ValidationError::CodecNotSuited {
                kind: self.kind,
                codec: self.codec,
            });
        }
        let raw = self.format.raw_len(size);
        let (min, max) = self.codec.encoded_len_range(self.format, raw);
        let max = max.min(limits.max_payload);
        if self.payload_len < min || self.payload_len > max {
            return Err(ValidationError::PayloadLength {
                kind: self.kind,
                codec: self.codec,
                len: self.payload_len,
                min,
                max,
            });
        }
        Ok(())
    }
}

/// An optional buffer beyond color, depth and motion, kept as raw
/// little-endian bytes in its [`BufferKind::canonical_format`].
#[derive(Clone, Debug, PartialEq)]
pub struct ExtraBuffer {
    /// What it holds (never a required kind).
    pub kind: BufferKind,
    /// Raw bytes, `size.pixels() × bytes_per_pixel` long.
    pub data: Vec<u8>,
}

/// A decoded rendered frame: metadata plus pixel buffers in row-major order,
/// top row first (DESIGN §3).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Index, time, camera, size, host time.
    pub meta: FrameMeta,
    /// Linear HDR color, RGBA f16 (alpha is 1 where the source had none).
    pub color: Vec<[f16; 4]>,
    /// Linear view depth; `+inf` for sky.
    pub depth: Vec<f32>,
    /// Motion current → previous, in pixels.
    pub motion: Vec<[f32; 2]>,
    /// Optional extra buffers, at most one per kind.
    pub extras: Vec<ExtraBuffer>,
}

impl Frame {
    /// Frame `index` at 60 fps of `size`: black, depth 1, no motion, a
    /// camera at the origin looking down −Z (aspect 2, near 0.1, no far
    /// plane). A starting point for tests and tools that fill in what they
    /// need.
    pub fn blank(index: u64, size: FrameSize) -> Self {
        let n = size.pixels() as usize;
        Self {
            meta: FrameMeta {
                index,
                time: index as f64 / 60.0,
                camera: Camera::new(
                    crate::Pose::new(glam::DVec3::ZERO, glam::DQuat::IDENTITY),
                    crate::Projection::perspective(1.0, 2.0, 0.1, f64::INFINITY),
                ),
                size,
                host_processing: Duration::ZERO,
                cut: false,
            },
            color: vec![[f16::ZERO; 4]; n],
            depth: vec![1.0; n],
            motion: vec![[0.0; 2]; n],
            extras: vec![],
        }
    }

    /// A frame with `meta` and no pixel data yet, for decoders to fill.
    pub fn empty(meta: FrameMeta) -> Self {
        Self {
            meta,
            color: Vec::new(),
            depth: Vec::new(),
            motion: Vec::new(),
            extras: Vec::new(),
        }
    }

    /// Checks metadata and that every buffer has one entry per pixel.
    pub fn validate(&self, limits: &Limits) -> Result<(), ValidationError> {
        self.meta.validate(limits)?;
        let n = self.meta.size.pixels();
        let check = |kind, len: usize, bpp: u64| {
            let want = n.saturating_mul(bpp);
            if len as u64 != want {
                Err(ValidationError::PayloadLength {
                    kind,
                    codec: Codec::Raw,
                    len: len as u64,
                    min: want,
                    max: want,
                })
            } else {
                Ok(())
            }
        };
        check(BufferKind::Color, self.color.len(), 1)?;
        check(BufferKind::Depth, self.depth.len(), 1)?;
        check(BufferKind::Motion, self.motion.len(), 1)?;
        for (i, extra) in self.extras.iter().enumerate() {
            if extra.kind.is_required() || self.extras[..i].iter().any(|e| e.kind == extra.kind) {
                return Err(ValidationError::DuplicateBuffer(extra.kind));
            }
            let bpp = extra.kind.canonical_format().bytes_per_pixel();
            check(extra.kind, extra.data.len(), u64::from(bpp))?;
        }
        Ok(())
    }

    /// The buffer `kind` serialised in `format` (little-endian, interleaved).
    /// Fails if the frame lacks the buffer or the format does not suit it.
    pub fn buffer_bytes(
        &self,
        kind: BufferKind,
        format: PixelFormat,
    ) -> Result<Vec<u8>, ValidationError> {
        if !kind.allowed_formats().contains(&format) {
            return Err(ValidationError::FormatNotAllowed { kind, format });
        }
        // Sized by the buffers themselves, not by the (maybe unvalidated)
        // frame size.
        let (colors, depths, motions) = (self.color.len(), self.depth.len(), self.motion.len());
        Ok(match (kind, format) {
            (BufferKind::Color, PixelFormat::Rgba16Float) => {
                le_bytes(self.color.iter().flatten(), 4 * colors, |v| v.to_le_bytes())
            }
            (BufferKind::Color, _) => {
                le_bytes(self.color.iter().flat_map(|p| &p[..3]), 3 * colors, |v| {
                    v.to_le_bytes()
                })
            }
            (BufferKind::Depth, _) => le_bytes(self.depth.iter(), depths, |v| v.to_le_bytes()),
            (BufferKind::Motion, PixelFormat::Rg16Float) => {
                le_bytes(self.motion.iter().flatten(), 2 * motions, |v| {
                    f16::from_f32(*v).to_le_bytes()
                })
            }
            (BufferKind::Motion, _) => le_bytes(self.motion.iter().flatten(), 2 * motions, |v| {
                v.to_le_bytes()
            }),
            (kind, format) => {
                let extra = self
                    .extras
                    .iter()
                    .find(|e| e.kind == kind)
                    .ok_or(ValidationError::MissingBuffer(kind))?;
                convert_f16_channels(&extra.data, kind.canonical_format(), format)
            }
        })
    }

    /// Stores `bytes` (in `format`, already length-checked against the frame
    /// size) as buffer `kind`, converting to the canonical in-memory format.
    pub fn set_buffer_bytes(
        &mut self,
        kind: BufferKind,
        format: PixelFormat,
        bytes: &[u8],
    ) -> Result<(), ValidationError> {
        if !kind.allowed_formats().contains(&format) {
            return Err(ValidationError::FormatNotAllowed { kind, format });
        }
        let expect = format.raw_len(self.meta.size);
        if bytes.len() as u64 != expect {
            return Err(ValidationError::PayloadLength {
                kind,
                codec: Codec::Raw,
                len: bytes.len() as u64,
                min: expect,
                max: expect,
            });
        }
        match (kind, format) {
            (BufferKind::Color, PixelFormat::Rgba16Float) => {
                self.color = bytes
                    .chunks_exact(8)
                    .map(|c| std::array::from_fn(|i| f16_at(c, i)))
                    .collect();
            }
            (BufferKind::Color, _) => {
                self.color = bytes
                    .chunks_exact(6)
                    .map(|c| [f16_at(c, 0), f16_at(c, 1), f16_at(c, 2), f16::ONE])
                    .collect();
            }
            (BufferKind::Depth, _) => {
                self.depth = bytes.chunks_exact(4).map(|c| f32_at(c, 0)).collect();
            }
            (BufferKind::Motion, PixelFormat::Rg16Float) => {
                self.motion = bytes
                    .chunks_exact(4)
                    .map(|c| [f16_at(c, 0).to_f32(), f16_at(c, 1).to_f32()])
                    .collect();
            }
            (BufferKind::Motion, _) => {
                self.motion = bytes
                    .chunks_exact(8)
                    .map(|c| [f32_at(c, 0), f32_at(c, 1)])
                    .collect();
            }
            (kind, format) => {
                let data = convert_f16_channels(bytes, format, kind.canonical_format());
                self.extras.retain(|e| e.kind != kind);
                self.extras.push(ExtraBuffer { kind, data });
            }
        }
        Ok(())
    }

    /// The buffer kinds this frame carries, required ones first.
    pub fn kinds(&self) -> impl Iterator<Item = BufferKind> + '_ {
        BufferKind::REQUIRED
            .into_iter()
            .chain(self.extras.iter().map(|e| e.kind))
    }

    /// Pixel index of `(x, y)`.
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.meta.size.width as usize + x as usize
    }
}

/// The little-endian bytes of `count` values (the capacity: a frame's
/// buffer is megabytes, which a byte-at-a-time `collect` grows and fills
/// slowly).
fn le_bytes<T, const N: usize>(
    values: impl Iterator<Item = T>,
    count: usize,
    bytes: impl Fn(T) -> [u8; N],
) -> Vec<u8> {
    let mut out = Vec::with_capacity(count * N);
    for v in values {
        out.extend_from_slice(&bytes(v));
    }
    out
}

fn f16_at(bytes: &[u8], i: usize) -> f16 {
    f16::from_le_bytes([bytes[2 * i], bytes[2 * i + 1]])
}

fn f32_at(bytes: &[u8], i: usize) -> f32 {
    f32::from_le_bytes([
        bytes[4 * i],
        bytes[4 * i + 1],
        bytes[4 * i + 2],
        bytes[4 * i + 3],
    ])
}

/// Converts between the f16 formats (RGB ↔ RGBA, alpha 1 when added) and
/// passes any other pair through unchanged (same-format copies).
fn convert_f16_channels(bytes: &[u8], from: PixelFormat, to: PixelFormat) -> Vec<u8> {
    match (from, to) {
        (PixelFormat::Rgba16Float, PixelFormat::Rgb16Float) => bytes
            .chunks_exact(8)
            .flat_map(|c| c[..6].iter().copied())
            .collect(),
        (PixelFormat::Rgb16Float, PixelFormat::Rgba16Float) => bytes
            .chunks_exact(6)
            .flat_map(|c| c.iter().copied().chain(f16::ONE.to_le_bytes()))
            .collect(),
        _ => bytes.to_vec(),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::{Pose, Projection};
    use glam::{DQuat, DVec3};

    /// A small synthetic frame with every value distinct, for round trips.
    pub(crate) fn sample_frame(index: u64, width: u32, height: u32) -> Frame {
        let size = FrameSize::new(width, height);
        let n = size.pixels() as usize;
        let camera = Camera::new(
            Pose::new(DVec3::new(1e5, 2.0, -3.5), DQuat::from_rotation_y(0.3)),
            Projection::perspective(1.0, f64::from(width) / f64::from(height), 0.05, 500.0),
        );
        Frame {
            meta: FrameMeta {
                index,
                time: index as f64 / 60.0,
                camera,
                size,
                host_processing: Duration::from_micros(4_250),
                cut: false,
            },
            color: (0..n)
                .map(|i| {
                    let v = i as f32 * 0.01;
                    [
                        f16::from_f32(v),
                        f16::from_f32(v * 2.0),
                        f16::from_f32(100.0 - v),
                        f16::ONE,
                    ]
                })
                .collect(),
            depth: (0..n)
                .map(|i| {
                    if i % 7 == 0 {
                        f32::INFINITY
                    } else {
                        0.5 + i as f32 * 0.25
                    }
                })
                .collect(),
            motion: (0..n)
                .map(|i| [i as f32 * 0.125 - 3.0, -(i as f32) * 0.5])
                .collect(),
            extras: vec![],
        }
    }

    #[test]
    fn sizes_parse_from_text_within_the_limits() {
        assert_eq!(
            "1280x720".parse::<FrameSize>().unwrap(),
            FrameSize::new(1280, 720)
        );
        for bad in ["1280", "x720", "12a0x720", "0x720", "9000x10", "-1x5", ""] {
            assert!(bad.parse::<FrameSize>().is_err(), "{bad}");
        }
        assert!(matches!(
            "640-360".parse::<FrameSize>(),
            Err(ParseSizeError::Format)
        ));
    }

    #[test]
    fn sizes_and_formats() {
        assert_eq!(PixelFormat::Rgba16Float.bytes_per_pixel(), 8);
        assert_eq!(PixelFormat::Rgb16Float.bytes_per_pixel(), 6);
        assert_eq!(
            PixelFormat::Rg32Float.raw_len(FrameSize::new(8192, 8192)),
            8192 * 8192 * 8
        );
        for kind in BufferKind::ALL {
            assert!(kind.allowed_formats().contains(&kind.canonical_format()));
        }
    }

    #[test]
    fn buffer_bytes_round_trip_every_allowed_format() {
        let mut f = sample_frame(3, 5, 4);
        f.extras.push(ExtraBuffer {
            kind: BufferKind::Mask,
            data: (0..20).collect(),
        });
        f.validate(&Limits::default()).unwrap();
        for kind in f.kinds().collect::<Vec<_>>() {
            for &format in kind.allowed_formats() {
                let bytes = f.buffer_bytes(kind, format).unwrap();
                assert_eq!(bytes.len() as u64, format.raw_len(f.meta.size));
                let mut g = f.clone();
                g.set_buffer_bytes(kind, format, &bytes).unwrap();
                if format == PixelFormat::Rg16Float {
                    // Half-precision motion is lossy: within f16 rounding.
                    for (a, b) in f.motion.iter().zip(&g.motion) {
                        for c in 0..2 {
                            assert!((a[c] - b[c]).abs() <= a[c].abs() * 1e-3 + 1e-3);
                        }
                    }
                } else {
                    assert_eq!(f, g, "{kind:?} {format:?}");
                }
            }
        }
    }

    /// A time or host processing time that arithmetic downstream cannot
    /// take is out of range (a host processing time near `u64::MAX`
    /// seconds used to pass and overflow the producer's `+=`).
    #[test]
    fn meta_validation_bounds_times() {
        let limits = Limits::default();
        let f = sample_frame(0, 4, 4);
        let range =
            |m: &FrameMeta| matches!(m.validate(&limits), Err(ValidationError::OutOfRange(_)));
        let mut m = f.meta;
        m.host_processing = Duration::from_secs(u64::MAX);
        assert!(range(&m));
        m.host_processing = MAX_HOST_PROCESSING;
        assert!(m.validate(&limits).is_ok());
        m.time = -1e10;
        assert!(range(&m));
        m.time = MAX_TIME;
        assert!(m.validate(&limits).is_ok());
    }

    #[test]
    fn validation_catches_wrong_lengths_and_formats() {
        let limits = Limits::default();
        let mut f = sample_frame(0, 4, 4);
        f.depth.pop();
        assert!(matches!(
            f.validate(&limits),
            Err(ValidationError::PayloadLength { .. })
        ));
        let f = sample_frame(0, 4, 4);
        assert!(matches!(
            f.buffer_bytes(BufferKind::Depth, PixelFormat::Rg16Float),
            Err(ValidationError::FormatNotAllowed { .. })
        ));
        let mut g = f.clone();
        assert!(
            g.set_buffer_bytes(BufferKind::Depth, PixelFormat::R32Float, &[0; 3])
                .is_err()
        );
        let desc = BufferDesc {
            kind: BufferKind::Depth,
            format: PixelFormat::R32Float,
            codec: Codec::Raw,
            payload_len: 63,
        };
        assert!(desc.validate(f.meta.size, &limits).is_err());
        assert!(
            BufferDesc {
                payload_len: 64,
                ..desc
            }
            .validate(f.meta.size, &limits)
            .is_ok()
        );
        let mut m = f.meta;
        m.size = FrameSize::new(8193, 1);
        assert!(matches!(
            m.validate(&limits),
            Err(ValidationError::BadSize { .. })
        ));
        m.size = FrameSize::new(4, 4);
        m.time = f64::NAN;
        assert!(matches!(
            m.validate(&limits),
            Err(ValidationError::NonFinite(_))
        ));
    }
}
