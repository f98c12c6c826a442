//! The H.264 decoder (FFmpeg's, through libavcodec): one payload in, one
//! picture out, or a typed error for that frame.

use ff::format::Pixel;
use ffmpeg_next as ff;
use half::f16;

use crate::transfer::{self, Chroma, Planes};
use crate::{FLAG_KEYFRAME, FLAG_YUV444, FLAGS, VideoError};

/// Decodes one stream's colour payloads, in the order they were encoded.
/// After an error (or [`ColorDecoder::gap`]) it refuses pictures with
/// [`VideoError::AwaitingKeyframe`] until a keyframe arrives: a picture
/// predicted from a missing or broken reference would be wrong everywhere
/// it moved.
pub struct ColorDecoder {
    decoder: ff::decoder::Video,
    picture: ff::frame::Video,
    planes: Planes,
    awaiting_keyframe: bool,
    /// Sequence number of the last payload decoded.
    last: Option<u32>,
}

impl ColorDecoder {
    /// A decoder waiting for its first keyframe. Fails if libavcodec lacks
    /// an H.264 decoder.
    pub fn new() -> Result<Self, VideoError> {
        crate::init()?;
        let codec =
            ff::decoder::find(ff::codec::Id::H264).ok_or(VideoError::Missing("H.264 decoder"))?;
        let mut context = ff::codec::context::Context::new_with_codec(codec);
        // Slice threads only: frame threads would hold pictures back.
        context.set_threading(ff::codec::threading::Config::kind(
            ff::codec::threading::Type::Slice,
        ));
        context.set_flags(ff::codec::Flags::LOW_DELAY);
        let mut decoder = context.decoder();
        // Report damage as errors rather than concealing it.
        decoder.check(
            ff::decoder::Check::CRC
                | ff::decoder::Check::BITSTREAM
                | ff::decoder::Check::BUFFER
                | ff::decoder::Check::EXPLODE,
        );
        let decoder = decoder
            .open_as(codec)
            .and_then(|d| d.video())
            .map_err(VideoError::ffmpeg("opening the H.264 decoder"))?;
        Ok(Self {
            decoder,
            picture: ff::frame::Video::empty(),
            planes: Planes::default(),
            awaiting_keyframe: true,
            last: None,
        })
    }

    /// A frame was lost before the next payload: wait for a keyframe.
    pub fn gap(&mut self) {
        self.awaiting_keyframe = true;
    }

    /// Whether the decoder needs a keyframe before it can decode again (the
    /// receiver should ask the sender for one).
    pub fn awaiting_keyframe(&self) -> bool {
        self.awaiting_keyframe
    }

    /// Decodes `payload` into `out` as `width × height` linear RGBA.
    pub fn decode(
        &mut self,
        payload: &[u8],
        width: u32,
        height: u32,
        out: &mut Vec<[f16; 4]>,
    ) -> Result<(), VideoError> {
        let result = self.decode_unit(payload, (width, height), out);
        if result.is_err() {
            self.awaiting_keyframe = true;
            // Drop whatever state the broken access unit left behind.
            self.decoder.flush();
        }
        result
    }

    /// [`ColorDecoder::decode`] without the recovery on error.
    fn decode_unit(
        &mut self,
        payload: &[u8],
        (width, height): (u32, u32),
        out: &mut Vec<[f16; 4]>,
    ) -> Result<(), VideoError> {
        let (&flags, rest) = payload
            .split_first()
            .ok_or(VideoError::BadPayload("empty"))?;
        if flags & !FLAGS != 0 {
            return Err(VideoError::BadPayload("unknown flags"));
        }
        let (sequence, rest) = rest
            .split_first_chunk::<4>()
            .ok_or(VideoError::BadPayload("no sequence number"))?;
        let sequence = u32::from_le_bytes(*sequence);
        let (peak, unit) = rest
            .split_first_chunk::<2>()
            .ok_or(VideoError::BadPayload("no peak"))?;
        let peak = f16::from_le_bytes(*peak);
        if !peak.is_finite() || peak < f16::ZERO {
            return Err(VideoError::BadPayload("peak not finite and non-negative"));
        }
        if unit.is_empty() {
            return Err(VideoError::BadPayload("no access unit"));
        }
        let keyframe = flags & FLAG_KEYFRAME != 0;
        if self.awaiting_keyframe && !keyframe {
            return Err(VideoError::AwaitingKeyframe);
        }
        // A predicted picture must follow the one it was predicted from.
        if let Some(last) = self.last.filter(|_| !keyframe) {
            if sequence != last.wrapping_add(1) {
                return Err(VideoError::Gap {
                    last,
                    got: sequence,
                });
            }
        }
        let chroma = if flags & FLAG_YUV444 != 0 {
            Chroma::Yuv444
        } else {
            Chroma::Yuv420
        };
        let (cw, ch) = transfer::coded_size(width, height, chroma);
        // The stream's parameter sets say how large a picture to allocate:
        // never much more than the frame the validated header announced
        // (macroblock rows and columns, and the decoder's edge, on top).
        // SAFETY: the context is open and owned by `self.decoder`;
        // `max_pixels` is a plain field libavcodec reads when it allocates.
        unsafe {
            (*self.decoder.as_mut_ptr()).max_pixels = (cw as i64 + 64) * (ch as i64 + 64);
        }
        self.decoder
            .send_packet(&ff::Packet::copy(unit))
            .map_err(VideoError::ffmpeg("decoding a packet"))?;
        match self.decoder.receive_frame(&mut self.picture) {
            Ok(()) => {}
            Err(ff::Error::Other { errno }) if errno == ff::util::error::EAGAIN => {
                return Err(VideoError::Delayed("decoder"));
            }
            Err(e) => return Err(VideoError::ffmpeg("receiving a picture")(e)),
        }
        // One packet, one picture: anything more is a stream we did not send.
        let mut extra = ff::frame::Video::empty();
        if self.decoder.receive_frame(&mut extra).is_ok() {
            return Err(VideoError::BadPayload("more than one picture"));
        }
        if self.picture.is_corrupt() {
            return Err(VideoError::Corrupt);
        }
        let want = match chroma {
            Chroma::Yuv420 => Pixel::YUV420P10LE,
            Chroma::Yuv444 => Pixel::YUV444P10LE,
        };
        let picture = &self.picture;
        if picture.format() != want
            || picture.width() as usize != cw
            || picture.height() as usize != ch
        {
            return Err(VideoError::WrongPicture {
                got_width: picture.width(),
                got_height: picture.height(),
                got_format: format!("{:?}", picture.format()),
                width,
                height,
                chroma,
            });
        }
        let (sx, sy) = chroma.subsampling();
        let planes = &mut self.planes;
        planes.width = cw;
        planes.height = ch;
        planes.chroma_width = cw / sx;
        for (index, plane, w, h) in [
            (0, &mut planes.y, cw, ch),
            (1, &mut planes.cb, cw / sx, ch / sy),
            (2, &mut planes.cr, cw / sx, ch / sy),
        ] {
            let stride = picture.stride(index);
            let data = picture.data(index);
            plane.clear();
            for row in 0..h {
                let src = data
                    .get(row * stride..row * stride + w * 2)
                    .ok_or(VideoError::BadPayload("short picture plane"))?;
                plane.extend(
                    src.chunks_exact(2)
                        .map(|b| u16::from_le_bytes([b[0], b[1]])),
                );
            }
        }
        transfer::from_planes(planes, width, height, chroma, peak, out);
        self.awaiting_keyframe = false;
        self.last = Some(sequence);
        Ok(())
    }
}
