//! The colour decoder (H.264 through libavcodec) on arbitrary payloads. The
//! first byte picks the frame size (a multiple of 16 by 16 pixels, up to
//! 128×64), the rest is split at `0xFF 0xFE 0xFD` into the payloads of
//! consecutive frames, decoded in order by one decoder. Each decode gives a
//! typed error or a picture of exactly the frame's pixels, every value
//! finite and not negative.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let width = 16 * (1 + u32::from(pick & 7));
    let height = 16 * (1 + u32::from((pick >> 3) & 3));
    let Ok(mut decoder) = video::ColorDecoder::new() else {
        return;
    };
    let mut out = Vec::new();
    let mut start = 0;
    let mut payloads = Vec::new();
    for i in 0..rest.len() {
        if rest[i..].starts_with(&[0xFF, 0xFE, 0xFD]) && i >= start {
            payloads.push(&rest[start..i]);
            start = i + 3;
        }
    }
    payloads.push(&rest[start.min(rest.len())..]);
    for payload in payloads {
        if decoder.decode(payload, width, height, &mut out).is_ok() {
            assert_eq!(out.len() as u32, width * height);
            for p in &out {
                for c in p {
                    assert!(c.is_finite() && c.to_f32() >= 0.0, "{c}");
                }
            }
        }
    }
});
