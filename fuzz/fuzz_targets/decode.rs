//! Feeds arbitrary bytes to every decoder of the wire format: the one-shot
//! message decoder, the streaming decoder (in chunks chosen by the input),
//! and the whole per-frame stream decoder (wire + reassembly + codecs,
//! video-coded colour through the `video` crate's H.264 decoder). Any
//! panic, hang or allocation beyond the limits is a bug.
#![no_main]

use libfuzzer_sys::fuzz_target;
use protocol::Limits;
use protocol::assemble::decode_frame_stream_with;
use protocol::wire::{Decoder, decode_message};

fuzz_target!(|data: &[u8]| {
    // Tight limits keep each run's memory small without changing the code paths.
    let limits = Limits {
        max_dimension: 512,
        max_pixels: 512 * 512,
        max_payload: 1 << 20,
        max_control: 64 << 10,
    };
    if let Ok((msg, used)) = decode_message(data, &limits) {
        assert!(used <= data.len());
        assert!(msg.validate(&limits).is_ok());
    }
    // The first byte picks the chunk size for the streaming decoder.
    // A decoder error ends only this part: the frame-stream decoder below
    // must see every input too (it used to be skipped for most of them).
    if let Some((&chunk, rest)) = data.split_first() {
        let mut decoder = Decoder::new(limits);
        'stream: for piece in rest.chunks(usize::from(chunk).max(1)) {
            decoder.feed(piece);
            loop {
                match decoder.next_message() {
                    Ok(Some(_)) => {}
                    Ok(None) => break,
                    Err(_) => break 'stream,
                }
            }
        }
    }
    let mut color = video::ColorDecoder::new().ok();
    let color = color
        .as_mut()
        .map(|d| d as &mut dyn protocol::codec::stream::ColorStreamDecoder);
    if let Ok(frame) = decode_frame_stream_with(data, &limits, color) {
        assert!(frame.validate(&limits).is_ok());
    }
});
