//! The decoders never panic: 120 000 random and mutated byte strings go
//! through the one-shot decoder, the streaming decoder and the frame stream
//! decoder, and every outcome is a message or a typed error.

mod common;

use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use protocol::assemble::{decode_frame_stream, encode_frame};
use protocol::wire::{self, Decoder, Message, StreamBuffer, WireError, decode_message};
use protocol::{Codec, Limits};

/// Applies 1..=4 random edits: bit flips, byte overwrites, truncation,
/// insertion, duplication of a slice, and rewrites of the length field.
fn mutate(rng: &mut StdRng, seed: &[u8]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..rng.random_range(1..=4) {
        if b.is_empty() {
            b.push(rng.random());
            continue;
        }
        let at = rng.random_range(0..b.len());
        match rng.random_range(0..7) {
            0 => b[at] ^= 1 << rng.random_range(0..8),
            1 => b[at] = rng.random(),
            2 => b.truncate(at),
            3 => {
                let n = rng.random_range(1..16);
                let junk: Vec<u8> = (0..n).map(|_| rng.random()).collect();
                b.splice(at..at, junk);
            }
            4 => {
                let end = (at + rng.random_range(1..64)).min(b.len());
                let piece = b[at..end].to_vec();
                b.extend_from_slice(&piece);
            }
            5 if b.len() >= 4 => {
                let len: u32 = match rng.random_range(0..3) {
                    0 => rng.random(),
                    1 => (b.len() as u32)
                        .wrapping_sub(wire::HEADER_LEN as u32)
                        .wrapping_add(rng.random_range(0..3)),
                    _ => u32::MAX,
                };
                b[..4].copy_from_slice(&len.to_le_bytes());
            }
            _ => {
                // Overwrite a varint-ish region with extreme values.
                let v: u8 = if rng.random() { 0xff } else { 0xfb };
                let end = (at + 9).min(b.len());
                b[at..end].fill(v);
            }
        }
    }
    b
}

/// Runs every decoder over `bytes`; returns how many messages decoded.
fn exercise(bytes: &[u8], limits: &Limits, rng: &mut StdRng) -> usize {
    let mut ok = 0;
    match decode_message(bytes, limits) {
        Ok((msg, used)) => {
            assert!(used <= bytes.len());
            assert!(
                msg.validate(limits).is_ok(),
                "decoder returned an invalid message"
            );
            ok += 1;
        }
        Err(e) => {
            // The first error is a real finding, never the poisoned state or
            // an encoder error.
            assert!(
                !matches!(e, WireError::Poisoned | WireError::Encode { .. }),
                "{e}"
            );
        }
    }
    let mut d = Decoder::new(*limits);
    let mut rest = bytes;
    while !rest.is_empty() {
        let n = rng.random_range(1..=rest.len().min(512));
        d.feed(&rest[..n]);
        rest = &rest[n..];
        loop {
            match d.next_message() {
                Ok(Some(_)) => ok += 1,
                Ok(None) => break,
                Err(WireError::Poisoned) => unreachable!("first error ends the loop"),
                Err(_) => {
                    assert!(matches!(d.next_message(), Err(WireError::Poisoned)));
                    return ok;
                }
            }
        }
    }
    ok
}

#[test]
fn hundred_thousand_random_and_mutated_inputs_never_panic() {
    let mut rng = StdRng::seed_from_u64(0x5eed_f00d);
    let limits = Limits::default();
    let seeds: Vec<Vec<u8>> = common::seed_messages()
        .iter()
        .map(|m| wire::encode(m).unwrap())
        .collect();
    let mut decoded = 0;
    let mut total = 0;
    // Pure random bytes, with and without a plausible header.
    for i in 0..40_000 {
        let n = rng.random_range(0..96);
        let mut b: Vec<u8> = (0..n).map(|_| rng.random()).collect();
        if i % 2 == 0 && b.len() >= wire::HEADER_LEN {
            b[4..6].copy_from_slice(&wire::WIRE_VERSION.to_le_bytes());
            b[6..8].copy_from_slice(&rng.random_range(1u16..=11).to_le_bytes());
            let len = (b.len() - wire::HEADER_LEN) as u32;
            b[..4].copy_from_slice(&len.to_le_bytes());
        }
        decoded += exercise(&b, &limits, &mut rng);
        total += 1;
    }
    // Mutations of valid messages of every kind.
    for _ in 0..80_000 {
        let seed = &seeds[rng.random_range(0..seeds.len())];
        let b = mutate(&mut rng, seed);
        decoded += exercise(&b, &limits, &mut rng);
        total += 1;
    }
    assert_eq!(total, 120_000);
    // Sanity: mutation leaves some inputs valid, so the decoders were really
    // reached beyond the header checks.
    assert!(decoded > 1_000, "only {decoded} inputs decoded");
}

#[test]
fn mutated_frame_streams_never_panic() {
    let mut rng = StdRng::seed_from_u64(7);
    let limits = Limits::default();
    let frame = {
        let seeds = common::seed_messages();
        let Some(Message::FrameHeader(h)) = seeds
            .into_iter()
            .find(|m| matches!(m, Message::FrameHeader(_)))
        else {
            panic!("no header seed");
        };
        let mut meta = h.meta;
        meta.size = protocol::FrameSize::new(24, 16);
        let n = 24 * 16;
        protocol::Frame {
            meta,
            color: vec![[half::f16::from_f32(0.5); 4]; n],
            depth: (0..n).map(|i| 1.0 + i as f32).collect(),
            motion: (0..n).map(|i| [i as f32 * 0.1, -0.5]).collect(),
            extras: vec![],
        }
    };
    let buffers = StreamBuffer::default_set(Codec::Zstd);
    let stream = encode_frame(&frame, &buffers, 1)
        .unwrap()
        .to_stream_bytes()
        .unwrap();
    let mut intact = 0;
    for _ in 0..3_000 {
        let b = mutate(&mut rng, &stream);
        if let Ok(f) = decode_frame_stream(&b, &limits) {
            assert!(f.validate(&limits).is_ok());
            intact += 1;
        }
    }
    // Most mutations must be caught (zstd checksums, lengths, validation).
    assert!(intact < 1_500, "{intact} of 3000 mutated streams decoded");
}
