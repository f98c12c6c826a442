//! Each codec's decoder on arbitrary payloads. The first byte picks the
//! codec (bit 0) and the pixel format (the rest, an index into
//! `PixelFormat::ALL`), the next two the pixel count (every expected
//! length up to 64 Ki pixels is reachable), the rest is the encoded
//! payload. A decode fails with a typed error or returns exactly the
//! expected length, and what it returns encodes and decodes to itself.
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
    let codec = [Codec::Raw, Codec::Zstd][usize::from(pick & 1)];
    let format = PixelFormat::ALL[usize::from(pick >> 1) % PixelFormat::ALL.len()];
    let expected = u64::from(u16::from_le_bytes(*count)) * u64::from(format.bytes_per_pixel());
    if let Ok(raw) = codec::decode(codec, format, payload, expected) {
        assert_eq!(raw.len() as u64, expected);
        let again = codec::encode(codec, format, &raw).expect("a decoded buffer encodes");
        let back = codec::decode(codec, format, &again, expected).expect("its encoding decodes");
        assert_eq!(back, raw);
    }
});
