//! What the stream does to a fed frame before the generator sees it (issue
//! 19): with [`BufferSet::Compact`], depth and motion are quantised by the
//! stream's codecs, coded against the fed frame before it (the previous
//! frame a server at the fed rate would send); with a colour codec
//! (`eval --color-codec h264@12`), colour goes through libx264 and FFmpeg's
//! decoder, one encoder per fed rate and colour setting, as a stream at
//! that rate would. Frames pass as rendered only when nothing is coded:
//! lossless geometry and one colour setting, `raw`.
//!
//! Each stream (fed rate and colour setting) keeps its costs: bytes per
//! buffer (Mbit/s at the fed rate), the decoded colour's display-space PSNR
//! and ꟻLIP against the rendered, and encode and decode wall time.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use half::f16;
use protocol::assemble::{encode_frame_after, encode_frame_with};
use protocol::codec::DEFAULT_ZSTD_LEVEL;
use protocol::codec::stream::{ColorStreamDecoder, ColorStreamEncoder, StreamError};
use protocol::wire::{BufferSet, StreamBuffer};
use protocol::{BufferKind, Codec, Frame, FrameMeta};
use serde::Serialize;
use video::transfer::display_psnr;
use video::{ColorCodec, ColorDecoder, ColorEncoder};

/// The stream's codecs between the renderer and the generator.
pub struct Transport {
    set: BufferSet,
    /// Whether frames are coded at all.
    coded: bool,
    /// The colour settings, in the order the command line gave them (the
    /// order of [`Transport::costs`] within a fed rate).
    colors: Vec<ColorCodec>,
    /// Display rate; a stream fed every `step`th frame runs at `fps / step`.
    fps: f64,
    /// Per (step, index into `colors`).
    streams: BTreeMap<(usize, usize), Stream>,
}

/// One stream's codec state and tallies: one fed rate, one colour setting.
struct Stream {
    buffers: [StreamBuffer; 3],
    color: Option<(ColorEncoder, ColorDecoder)>,
    frames: u64,
    bytes: BTreeMap<&'static str, u64>,
    psnr_sum: f64,
    psnr_min: f64,
    flip_sum: f64,
    /// 8-bit display channel values compared, and how many changed.
    codes: u64,
    codes_changed: u64,
    encode: Vec<Duration>,
    decode: Vec<Duration>,
    color_encode: Vec<Duration>,
    color_decode: Vec<Duration>,
}

/// A stream coder that adds the wall time of each frame it codes to a
/// tally: the colour codec's share of a frame's encode or decode.
struct Timed<'a, T>(&'a mut T, &'a mut Vec<Duration>);

impl<T: ColorStreamEncoder> ColorStreamEncoder for Timed<'_, T> {
    fn codec(&self) -> Codec {
        self.0.codec()
    }

    fn encode_color(
        &mut self,
        size: protocol::FrameSize,
        color: &[[f16; 4]],
    ) -> Result<Vec<u8>, StreamError> {
        let started = Instant::now();
        let payload = self.0.encode_color(size, color);
        self.1.push(started.elapsed());
        payload
    }
}

impl<T: ColorStreamDecoder> ColorStreamDecoder for Timed<'_, T> {
    fn codec(&self) -> Codec {
        self.0.codec()
    }

    fn decode_color(
        &mut self,
        payload: &[u8],
        size: protocol::FrameSize,
        out: &mut Vec<[f16; 4]>,
    ) -> Result<(), StreamError> {
        let started = Instant::now();
        let result = self.0.decode_color(payload, size, out);
        self.1.push(started.elapsed());
        result
    }
}

/// What one stream (fed rate and colour setting) cost (`report.json`'s
/// `scenes[].stream`).
#[derive(Clone, Debug, Serialize)]
pub struct StreamCost {
    /// Frames per second of the stream (the display rate / the step).
    pub fps: f64,
    /// Every how many displayed frames one is fed.
    pub step: usize,
    /// Frames coded.
    pub frames: u64,
    /// The colour setting as given (`raw`, `h264@8`, `h264`, ...): what
    /// a variant's [`Variant::color`](super::variant::Variant::color) names.
    pub setting: String,
    /// The colour codec as run (the automatic rate resolved to Mbit/s).
    pub color_codec: String,
    /// Mbit/s of each buffer at the stream's rate (`color`, `depth`, `motion`).
    pub mbit: BTreeMap<&'static str, f64>,
    /// All buffers together.
    pub total_mbit: f64,
    /// Decoded colour against the rendered, display space: mean and worst
    /// frame (dB); `None` when colour is not video-coded.
    pub color_psnr: Option<(f64, f64)>,
    /// Mean ꟻLIP of the decoded colour against the rendered.
    pub color_flip: Option<f64>,
    /// Share of the 8-bit display channel values (what ꟻLIP compares)
    /// that the codec changed. ꟻLIP weighs even one-code changes: on a
    /// grey ramp, one code up everywhere scores 0.034 and in one pixel of
    /// ten 0.005 (`measure::tests::flip_weighs_one_code_changes`).
    pub color_codes_changed: Option<f64>,
    /// Median wall time to encode a frame (all buffers), ms.
    pub encode_ms: f64,
    /// Median wall time to decode one, ms.
    pub decode_ms: f64,
    /// Of which the colour codec: median encode and decode ms.
    pub color_ms: Option<(f64, f64)>,
}

fn kind_name(kind: BufferKind) -> &'static str {
    match kind {
        BufferKind::Color => "color",
        BufferKind::Depth => "depth",
        BufferKind::Motion => "motion",
        _ => "extra",
    }
}

fn median_ms(v: &[Duration]) -> f64 {
    let mut ms: Vec<f64> = v.iter().map(|d| d.as_secs_f64() * 1e3).collect();
    ms.sort_by(f64::total_cmp);
    ms.get(ms.len() / 2).copied().unwrap_or(0.0)
}

impl Transport {
    /// Fed frames through `set`'s depth and motion codecs and colour
    /// through each of `colors` (a stream each); `fps` is the display rate.
    pub fn new(set: BufferSet, colors: &[ColorCodec], fps: f64) -> Self {
        let mut unique: Vec<ColorCodec> = Vec::new();
        for &c in colors {
            if !unique.contains(&c) {
                unique.push(c);
            }
        }
        Self {
            set,
            coded: set == BufferSet::Compact || unique.iter().any(|&c| c != ColorCodec::Raw),
            colors: unique,
            fps,
            streams: BTreeMap::new(),
        }
    }

    /// `frame` as a client decodes it, when it is fed every `step`th
    /// displayed frame with its colour through `color` (one of the
    /// settings given to [`Transport::new`]) and `previous` was the frame
    /// sent before it.
    pub fn carry(
        &mut self,
        mut frame: Frame,
        previous: Option<&FrameMeta>,
        step: usize,
        color: ColorCodec,
    ) -> anyhow::Result<Frame> {
        if !self.coded {
            return Ok(frame);
        }
        let which = self
            .colors
            .iter()
            .position(|&c| c == color)
            .ok_or_else(|| {
                anyhow::anyhow!("colour setting {color} was not given to the transport")
            })?;
        let fps = self.fps / step.max(1) as f64;
        let stream = match self.streams.entry((step, which)) {
            std::collections::btree_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::btree_map::Entry::Vacant(e) => e.insert(Stream {
                buffers: self.set.buffers(color.codec()),
                color: match color.settings(frame.meta.size, fps) {
                    Some(s) => Some((ColorEncoder::new(s, fps)?, ColorDecoder::new()?)),
                    None => None,
                },
                frames: 0,
                bytes: BTreeMap::new(),
                psnr_sum: 0.0,
                psnr_min: f64::INFINITY,
                flip_sum: 0.0,
                codes: 0,
                codes_changed: 0,
                encode: Vec::new(),
                decode: Vec::new(),
                color_encode: Vec::new(),
                color_decode: Vec::new(),
            }),
        };
        let started = Instant::now();
        let (encoded, decoded) = match &mut stream.color {
            Some((encoder, decoder)) => {
                let mut timed = Timed(encoder, &mut stream.color_encode);
                let encoded = encode_frame_with(
                    &frame,
                    previous,
                    &stream.buffers,
                    DEFAULT_ZSTD_LEVEL,
                    Some(&mut timed),
                )?;
                stream.encode.push(started.elapsed());
                let started = Instant::now();
                let decoded =
                    encoded.decode_with(Some(&mut Timed(decoder, &mut stream.color_decode)))?;
                stream.decode.push(started.elapsed());
                (encoded, decoded)
            }
            None => {
                let encoded =
                    encode_frame_after(&frame, previous, &stream.buffers, DEFAULT_ZSTD_LEVEL)?;
                stream.encode.push(started.elapsed());
                let started = Instant::now();
                let decoded = encoded.decode()?;
                stream.decode.push(started.elapsed());
                (encoded, decoded)
            }
        };
        let mut decoded = decoded;
        stream.frames += 1;
        for (desc, payload) in encoded.header.buffers.iter().zip(&encoded.payloads) {
            *stream.bytes.entry(kind_name(desc.kind)).or_default() += payload.data.len() as u64;
        }
        if stream.color.is_some() {
            let q = display_psnr(&frame.color, &decoded.color);
            stream.psnr_sum += q;
            stream.psnr_min = stream.psnr_min.min(q);
            let size = frame.meta.size;
            let display = |c: &[[f16; 4]]| {
                protocol::display::display_encode(size.width, size.height, c)
                    .ok_or_else(|| anyhow::anyhow!("colour of the wrong size"))
            };
            let (rendered, received) = (display(&frame.color)?, display(&decoded.color)?);
            let (a, b) = (rendered.to_rgb8(), received.to_rgb8());
            stream.codes += a.len() as u64;
            stream.codes_changed += a.iter().zip(&b).filter(|(x, y)| x != y).count() as u64;
            let flip = super::measure::flip_map(&rendered, &received);
            let values = flip.to_vec();
            stream.flip_sum +=
                values.iter().map(|&v| f64::from(v)).sum::<f64>() / values.len().max(1) as f64;
        }
        // The generator sees the decoded frame, with the rendered metadata
        // (host timings and all).
        std::mem::swap(&mut frame.color, &mut decoded.color);
        frame.depth = decoded.depth;
        frame.motion = decoded.motion;
        Ok(frame)
    }

    /// What each stream cost so far: slowest fed rate first, colour
    /// settings in the order given.
    pub fn costs(&self) -> Vec<StreamCost> {
        let mut streams: Vec<_> = self.streams.iter().filter(|(_, s)| s.frames > 0).collect();
        streams.sort_by_key(|((step, which), _)| (std::cmp::Reverse(*step), *which));
        streams
            .into_iter()
            .map(|(&(step, which), s)| {
                let fps = self.fps / step.max(1) as f64;
                let mbit: BTreeMap<&'static str, f64> = s
                    .bytes
                    .iter()
                    .map(|(&k, &b)| (k, b as f64 * 8.0 * fps / s.frames as f64 / 1e6))
                    .collect();
                StreamCost {
                    fps,
                    step,
                    frames: s.frames,
                    setting: self.colors[which].to_string(),
                    color_codec: s.color.as_ref().map_or_else(
                        || self.colors[which].to_string(),
                        |(encoder, _)| encoder.settings().to_string(),
                    ),
                    total_mbit: mbit.values().sum(),
                    mbit,
                    color_psnr: s
                        .color
                        .as_ref()
                        .map(|_| (s.psnr_sum / s.frames as f64, s.psnr_min)),
                    color_flip: s.color.as_ref().map(|_| s.flip_sum / s.frames as f64),
                    color_codes_changed: s
                        .color
                        .as_ref()
                        .map(|_| s.codes_changed as f64 / s.codes.max(1) as f64),
                    encode_ms: median_ms(&s.encode),
                    decode_ms: median_ms(&s.decode),
                    color_ms: s
                        .color
                        .as_ref()
                        .map(|_| (median_ms(&s.color_encode), median_ms(&s.color_decode))),
                }
            })
            .collect()
    }
}
