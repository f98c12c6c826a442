//! Each codec's decoder on arbitrary payloads. The first byte picks the
//! codec (an index into `Codec::ALL`, modulo its length) and the pixel
//! format (the quotient, an index into `PixelFormat::ALL`), the next two the pixel count
//! (every expected length up to 64 Ki pixels is reachable), the rest is the
//! encoded payload. A decode fails with a typed error or returns exactly
//! the expected length; what a lossless codec returns encodes and decodes
//! to itself, and what the quantised ones return is in their range (depth
//! not negative, motion finite; motion decodes against a fixed depth). A
//! video codec is refused here: its payloads need the stream's decoder
//! (fuzzed by the `video` target).
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::codec::{self, Codec};
use protocol::frame::PixelFormat;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let Some((count, payload)) = rest.split_first_chunk::<2>() else {
        return;
    };
    let n = Codec::ALL.len();
    let codec = Codec::ALL[usize::from(pick) % n];
    let format = PixelFormat::ALL[usize::from(pick) / n % PixelFormat::ALL.len()];
    let pixels = usize::from(u16::from_le_bytes(*count));
    let expected = pixels as u64 * u64::from(format.bytes_per_pixel());
    let depth: Vec<f32> = (0..pixels)
        .map(|i| if i % 5 == 0 { f32::INFINITY } else { 0.5 + i as f32 * 0.01 })
        .collect();
    let Ok(raw) = codec::decode_with(codec, format, payload, expected, Some(&depth)) else {
        return;
    };
    assert_eq!(raw.len() as u64, expected);
    match codec {
        Codec::Raw | Codec::Zstd => {
            let again = codec::encode(codec, format, &raw).expect("a decoded buffer encodes");
            let back = codec::decode(codec, format, &again, expected).expect("its encoding decodes");
            assert_eq!(back, raw);
        }
        Codec::QuantDepth => {
            for v in raw.chunks_exact(4) {
                let d = f32::from_le_bytes([v[0], v[1], v[2], v[3]]);
                assert!(!(d < 0.0), "negative depth {d}");
            }
        }
        Codec::H264 => panic!("a video payload decoded without the stream's decoder"),
        Codec::MotionResidual => {
            let unit = format.channel_bytes() as usize;
            for v in raw.chunks_exact(unit) {
                let m = if unit == 2 {
                    half::f16::from_le_bytes([v[0], v[1]]).to_f32()
                } else {
                    f32::from_le_bytes([v[0], v[1], v[2], v[3]])
                };
                // f16 saturates to infinity above 65504: only f32 is finite
                // by construction.
                assert!(!m.is_nan(), "NaN motion");
                assert!(unit == 2 || m.is_finite(), "motion {m}");
            }
        }
    }
});
