//! Colour through a real video codec (issue 19 §1): libavcodec's H.264,
//! encoded by libx264 (the encoder Sunshine and most game streamers use) and
//! decoded by FFmpeg's decoder, never hand-written.
//!
//! * [`transfer`] decides what the codec carries for HDR colour: the fixed
//!   display transform's output at 10 bits, inverted on receipt.
//! * [`ColorEncoder`] keeps a low-latency configuration: no B-frames, no
//!   look-ahead, one frame in and its packet out before the next, a VBV of one
//!   frame at the target bitrate, a keyframe on request.
//! * [`ColorDecoder`] turns one payload into one picture or a typed
//!   [`VideoError`] for that frame; after an error it waits for a keyframe
//!   rather than showing pictures predicted from a broken reference.
//!
//! A payload is one flags byte (keyframe, chroma), a sequence number (`u32`
//! LE, one more than the payload before it, so a receiver knows when it
//! missed one), the frame's peak linear value (`f16` LE,
//! [`transfer::peak`]), then the H.264 Annex B access unit.
//!
//! Both coders implement protocol's stream traits
//! ([`protocol::codec::stream`]) for [`protocol::Codec::H264`].

use std::fmt;
use std::str::FromStr;

mod decoder;
mod encoder;
pub mod transfer;

pub use decoder::ColorDecoder;
pub use encoder::ColorEncoder;
pub use transfer::Chroma;

/// Payload flag: the access unit is an IDR picture.
const FLAG_KEYFRAME: u8 = 1;
/// Payload flag: chroma is coded at full resolution.
const FLAG_YUV444: u8 = 2;
/// Every flag a payload may carry.
const FLAGS: u8 = FLAG_KEYFRAME | FLAG_YUV444;
/// Bytes before the access unit: flags, sequence number, peak.
const HEADER: usize = 1 + 4 + 2;

/// Whether `payload` carries a keyframe: a decoder that lost its reference
/// can start again from it.
pub fn is_keyframe(payload: &[u8]) -> bool {
    payload.first().is_some_and(|f| f & FLAG_KEYFRAME != 0)
}

/// A colour encoding setting: `h264@MBIT` (4:2:0) or `h264-444@MBIT`, the
/// bitrate in Mbit/s at the stream's frame rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VideoSettings {
    /// Target bitrate, bits per second.
    pub bitrate: u64,
    /// Chroma sampling.
    pub chroma: Chroma,
}

impl VideoSettings {
    /// Bits a frame at `fps`.
    pub fn bits_per_frame(&self, fps: f64) -> f64 {
        self.bitrate as f64 / fps.max(1e-3)
    }
}

impl fmt::Display for VideoSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = match self.chroma {
            Chroma::Yuv420 => "h264",
            Chroma::Yuv444 => "h264-444",
        };
        write!(f, "{name}@{}", self.bitrate as f64 / 1e6)
    }
}

/// A colour setting that does not parse.
#[derive(Debug, thiserror::Error)]
#[error(
    "`{0}` is not a colour codec: expected raw, zstd, h264, h264-444, h264@MBIT or h264-444@MBIT (e.g. h264@12)"
)]
pub struct ParseSettingsError(String);

impl FromStr for VideoSettings {
    type Err = ParseSettingsError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || ParseSettingsError(s.to_owned());
        let (name, rate) = s.split_once('@').ok_or_else(bad)?;
        let chroma = match name {
            "h264" => Chroma::Yuv420,
            "h264-444" => Chroma::Yuv444,
            _ => return Err(bad()),
        };
        let mbit: f64 = rate.parse().map_err(|_| bad())?;
        if !(0.05..=1000.0).contains(&mbit) {
            return Err(bad());
        }
        Ok(Self {
            bitrate: (mbit * 1e6).round() as u64,
            chroma,
        })
    }
}

/// Bits a pixel a frame that [`ColorCodec::H264`] spends when no bitrate
/// is named: 16.6 Mbit/s for 1280×720 at 30 fps (with the compact geometry,
/// inside the 25 Mbit/s for the whole stream), 4.1 Mbit/s for
/// 640×360, whose encode then stays within 10 ms here.
pub const AUTO_BITS_PER_PIXEL: f64 = 0.6;

impl VideoSettings {
    /// The setting [`AUTO_BITS_PER_PIXEL`] gives a stream of `size` at
    /// `fps`.
    pub fn auto(chroma: Chroma, size: protocol::FrameSize, fps: f64) -> Self {
        let fps = if fps.is_finite() && fps > 0.0 {
            fps
        } else {
            30.0
        };
        let bits = size.pixels() as f64 * fps * AUTO_BITS_PER_PIXEL;
        Self {
            bitrate: (bits.round() as u64).clamp(50_000, 1_000_000_000),
            chroma,
        }
    }
}

/// A stream's colour codec as a command line names it: `raw` (f16 as
/// rendered) and `zstd` (lossless) for research; `h264` (4:2:0) or
/// `h264-444`, at `@MBIT` Mbit/s or, without, at [`AUTO_BITS_PER_PIXEL`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ColorCodec {
    /// Uncompressed f16.
    Raw,
    /// Lossless zstd of the f16 values.
    Zstd,
    /// Through H.264.
    H264 {
        /// Chroma sampling.
        chroma: Chroma,
        /// Bits per second; `None` for [`AUTO_BITS_PER_PIXEL`].
        bitrate: Option<u64>,
    },
}

impl ColorCodec {
    /// The default of `serve` and `run`: H.264 at the automatic rate.
    pub const DEFAULT_LIVE: ColorCodec = ColorCodec::H264 {
        chroma: Chroma::Yuv420,
        bitrate: None,
    };

    /// The wire codec of the colour buffer.
    pub fn codec(self) -> protocol::Codec {
        match self {
            ColorCodec::Raw => protocol::Codec::Raw,
            ColorCodec::Zstd => protocol::Codec::Zstd,
            ColorCodec::H264 { .. } => protocol::Codec::H264,
        }
    }

    /// The encoder's setting for a stream of `size` at `fps`, if colour
    /// is video-coded.
    pub fn settings(self, size: protocol::FrameSize, fps: f64) -> Option<VideoSettings> {
        match self {
            ColorCodec::Raw | ColorCodec::Zstd => None,
            ColorCodec::H264 {
                chroma,
                bitrate: Some(bitrate),
            } => Some(VideoSettings { bitrate, chroma }),
            ColorCodec::H264 {
                chroma,
                bitrate: None,
            } => Some(VideoSettings::auto(chroma, size, fps)),
        }
    }
}

impl From<VideoSettings> for ColorCodec {
    fn from(s: VideoSettings) -> Self {
        ColorCodec::H264 {
            chroma: s.chroma,
            bitrate: Some(s.bitrate),
        }
    }
}

impl FromStr for ColorCodec {
    type Err = ParseSettingsError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(match s {
            "raw" => ColorCodec::Raw,
            "zstd" => ColorCodec::Zstd,
            "h264" => ColorCodec::H264 {
                chroma: Chroma::Yuv420,
                bitrate: None,
            },
            "h264-444" => ColorCodec::H264 {
                chroma: Chroma::Yuv444,
                bitrate: None,
            },
            _ => s.parse::<VideoSettings>()?.into(),
        })
    }
}

impl fmt::Display for ColorCodec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            ColorCodec::Raw => f.write_str("raw"),
            ColorCodec::Zstd => f.write_str("zstd"),
            ColorCodec::H264 {
                chroma,
                bitrate: Some(bitrate),
            } => VideoSettings { bitrate, chroma }.fmt(f),
            ColorCodec::H264 {
                chroma: Chroma::Yuv420,
                bitrate: None,
            } => f.write_str("h264"),
            ColorCodec::H264 {
                chroma: Chroma::Yuv444,
                bitrate: None,
            } => f.write_str("h264-444"),
        }
    }
}

/// Why a frame's colour could not be encoded or decoded.
#[derive(Debug, thiserror::Error)]
pub enum VideoError {
    /// libavcodec lacks a codec this crate needs.
    #[error(
        "libavcodec has no {0}: install FFmpeg with libx264 (Debian: libavcodec59, libx264-164)"
    )]
    Missing(&'static str),
    /// libavcodec refused an operation.
    #[error("{what}: {source}")]
    Ffmpeg {
        /// What was being done.
        what: &'static str,
        /// libavcodec's error.
        #[source]
        source: ffmpeg_next::Error,
    },
    /// The colour does not hold the frame's pixels.
    #[error("colour of {got} pixels for a {width}x{height} frame")]
    WrongPixels {
        /// Pixels given.
        got: usize,
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
    },
    /// The payload is empty or its flags byte is unknown.
    #[error("bad colour payload: {0}")]
    BadPayload(&'static str),
    /// Pictures after an error or a gap are skipped until a keyframe.
    #[error("waiting for a keyframe after an error or a gap")]
    AwaitingKeyframe,
    /// A payload was missed: this one is not the next in sequence.
    #[error("payload {got} follows payload {last}: the ones between were lost")]
    Gap {
        /// The last payload decoded.
        last: u32,
        /// This one.
        got: u32,
    },
    /// The decoder produced a picture unlike the frame's.
    #[error(
        "decoded a {got_width}x{got_height} {got_format} picture for a {width}x{height} {chroma:?} frame"
    )]
    WrongPicture {
        /// Decoded width.
        got_width: u32,
        /// Decoded height.
        got_height: u32,
        /// Decoded pixel format.
        got_format: String,
        /// Frame width.
        width: u32,
        /// Frame height.
        height: u32,
        /// Chroma the payload announced.
        chroma: Chroma,
    },
    /// The decoder flagged the picture as corrupt.
    #[error("the decoded picture is corrupt")]
    Corrupt,
    /// One frame in did not give one packet or picture out.
    #[error("the {0} held a frame back (the stream is one in, one out)")]
    Delayed(&'static str),
}

impl VideoError {
    fn ffmpeg(what: &'static str) -> impl FnOnce(ffmpeg_next::Error) -> Self {
        move |source| VideoError::Ffmpeg { what, source }
    }
}

/// Initialises libavcodec once (idempotent) and routes its log to warnings
/// only.
fn init() -> Result<(), VideoError> {
    static INIT: std::sync::OnceLock<Result<(), ffmpeg_next::Error>> = std::sync::OnceLock::new();
    (*INIT.get_or_init(|| {
        ffmpeg_next::init()?;
        ffmpeg_next::util::log::set_level(ffmpeg_next::util::log::Level::Error);
        Ok(())
    }))
    .map_err(|source| VideoError::Ffmpeg {
        what: "initialising libavcodec",
        source,
    })
}

impl protocol::codec::stream::ColorStreamEncoder for ColorEncoder {
    fn codec(&self) -> protocol::Codec {
        protocol::Codec::H264
    }

    fn encode_color(
        &mut self,
        size: protocol::FrameSize,
        color: &[[half::f16; 4]],
    ) -> Result<Vec<u8>, protocol::codec::stream::StreamError> {
        Ok(self.encode(size.width, size.height, color)?)
    }
}

impl protocol::codec::stream::ColorStreamDecoder for ColorDecoder {
    fn codec(&self) -> protocol::Codec {
        protocol::Codec::H264
    }

    fn decode_color(
        &mut self,
        payload: &[u8],
        size: protocol::FrameSize,
        out: &mut Vec<[half::f16; 4]>,
    ) -> Result<(), protocol::codec::stream::StreamError> {
        Ok(self.decode(payload, size.width, size.height, out)?)
    }
}

#[cfg(test)]
mod tests;
