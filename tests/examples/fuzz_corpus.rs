//! Writes the fuzz targets' seed corpus (`fuzz/seeds/<target>/`) from real
//! data: frames of the analytic scene encoded as they travel (raw, zstd
//! and H.264 colour), the handshake messages, each encoded buffer for the codec
//! target, and a one-frame native dump's files for the readers.
//!
//! `cargo run -p tests --example fuzz_corpus [-- DIR]` (default `fuzz/seeds`).

use std::path::{Path, PathBuf};

use glam::DVec3;
use protocol::assemble::{encode_frame, encode_frame_with};
use protocol::codec::stream::ColorStreamEncoder;
use protocol::codec::{Codec, DEFAULT_ZSTD_LEVEL};
use protocol::dump::{DumpWriter, Manifest, frame_paths};
use protocol::wire::{self, Hello, Message, StreamBuffer, WIRE_VERSION, WindowMode};
use protocol::{FrameSize, PixelFormat};

const SIZE: FrameSize = FrameSize::new(16, 9);

/// The codec target's format byte for `format`: its index in
/// `PixelFormat::ALL` (see `fuzz/fuzz_targets/codec.rs`).
fn format_index(format: PixelFormat) -> u8 {
    PixelFormat::ALL
        .iter()
        .position(|&f| f == format)
        .expect("every format is in ALL") as u8
}

/// `bytes` as the receiver target's events on `stream`: data events (an op
/// byte, a length byte for `len × 16 + 1` bytes, the bytes), then its end.
fn events(stream: u8, bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut out = vec![];
    let mut rest = bytes;
    while !rest.is_empty() {
        let len = ((rest.len() - 1) / 16).min(15);
        let (chunk, tail) = rest.split_at(len * 16 + 1);
        out.push([&[stream << 2, len as u8][..], chunk].concat());
        rest = tail;
    }
    out.push(vec![stream << 2 | 1]);
    out
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join(name), bytes)?;
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let out = std::env::args()
        .nth(1)
        .map_or_else(|| PathBuf::from("fuzz/seeds"), PathBuf::from);
    let frames: Vec<_> = (0..2)
        .map(|i| tests::render(i, 60.0, DVec3::ZERO, SIZE))
        .collect();
    let sets = [
        StreamBuffer::default_set(Codec::Raw),
        StreamBuffer::default_set(Codec::Zstd),
        StreamBuffer::compact_set(Codec::Zstd),
        StreamBuffer::compact_set(Codec::H264),
    ];
    for (c, buffers) in sets.iter().enumerate() {
        // One colour stream per set, from its keyframe on.
        let mut color = video::ColorEncoder::new("h264@0.5".parse()?, 30.0)?;
        for (i, frame) in frames.iter().enumerate() {
            let previous = i.checked_sub(1).map(|p| &frames[p].meta);
            let encoder = (buffers[0].codec == Codec::H264)
                .then_some(&mut color as &mut dyn ColorStreamEncoder);
            let encoded = encode_frame_with(frame, previous, buffers, DEFAULT_ZSTD_LEVEL, encoder)?;
            write(
                &out.join("decode"),
                &format!("frame-{c}-{i}"),
                &encoded.to_stream_bytes()?,
            )?;
            for (b, (payload, desc)) in encoded
                .payloads
                .iter()
                .zip(&encoded.header.buffers)
                .enumerate()
            {
                // The codec target decodes no video (the decode and video
                // targets do).
                if desc.codec == Codec::H264 {
                    continue;
                }
                // The codec target's first byte: the codec (an index in
                // the target's order, modulo their number), then the format.
                let n = Codec::ALL.len() as u8;
                let codec = Codec::ALL
                    .iter()
                    .position(|c| *c == desc.codec)
                    .unwrap_or(0) as u8;
                let pick = codec + format_index(desc.format) * n;
                let seed = [
                    &[pick][..],
                    &(SIZE.pixels() as u16).to_le_bytes(),
                    &payload.data,
                ]
                .concat();
                write(&out.join("codec"), &format!("buffer-{c}-{i}-{b}"), &seed)?;
            }
        }
    }
    // The video target: its first byte picks 64×32 (see
    // `fuzz/fuzz_targets/video.rs`); a keyframe, then two predicted frames
    // of a moving camera, split by its separator.
    let size = FrameSize::new(64, 32);
    let mut encoder = video::ColorEncoder::new("h264@0.5".parse()?, 30.0)?;
    let mut seed = vec![3 | 1 << 3];
    for i in 0..3 {
        let frame = tests::render(i, 30.0, DVec3::ZERO, size);
        if i > 0 {
            seed.extend_from_slice(&[0xFF, 0xFE, 0xFD]);
        }
        seed.extend(encoder.encode(size.width, size.height, &frame.color)?);
    }
    write(&out.join("video"), "three-frames", &seed)?;
    let streams = frames
        .iter()
        .map(|f| {
            encode_frame(
                f,
                &StreamBuffer::default_set(Codec::Zstd),
                DEFAULT_ZSTD_LEVEL,
            )?
            .to_stream_bytes()
        })
        .collect::<Result<Vec<_>, _>>()?;
    // The receiver target's input (see `fuzz/fuzz_targets/receiver.rs`):
    // an order byte (0 newest, 1 every frame), then events: frame 0 then
    // frame 1, each on its stream to its end; and frame 1 overtaking frame
    // 0, interleaved chunk by chunk, in either order, the transport having
    // opened both streams first in the second.
    let in_order = [
        vec![vec![0]],
        events(0, &streams[0]),
        events(1, &streams[1]),
    ]
    .concat();
    write(&out.join("receiver"), "in-order", &in_order.concat())?;
    let (late, early) = (events(2, &streams[0]), events(3, &streams[1]));
    let mut overtaken = vec![];
    for k in 0..late.len().max(early.len()) {
        for e in [early.get(k), late.get(k)].into_iter().flatten() {
            overtaken.extend_from_slice(e);
        }
    }
    write(
        &out.join("receiver"),
        "overtaken",
        &[&[0][..], &overtaken].concat(),
    )?;
    // An open event: the op's top bit with kind 3.
    let open = |stream: u8| 0x80 | stream << 2 | 3;
    write(
        &out.join("receiver"),
        "overtaken-every",
        &[&[1, open(2), open(3)][..], &overtaken].concat(),
    )?;
    for (target, token) in [("decode", "token"), ("hello", "fuzz-token")] {
        let hello = Message::Hello(Hello {
            version: WIRE_VERSION,
            client_name: "seed".into(),
            token: token.into(),
            codecs: Codec::ALL.to_vec(),
            max_size: FrameSize::new(8192, 8192),
            window_modes: vec![WindowMode::KeepDensity, WindowMode::KeepSize],
            extras: vec![],
        });
        write(&out.join(target), "hello", &wire::encode(&hello)?)?;
    }
    let dump = tempfile::tempdir()?;
    let mut writer = DumpWriter::create(dump.path(), Manifest::new(60.0, SIZE, "fuzz seed"))?;
    writer.write_frame(&frames[0])?;
    writer.finish()?;
    let (exr, meta) = frame_paths(dump.path(), 0);
    let seed = [
        std::fs::read(dump.path().join("manifest.json"))?,
        std::fs::read(meta)?,
        std::fs::read(exr)?,
    ]
    .join(&b"\n--\n"[..]);
    write(&out.join("files"), "dump", &seed)?;
    println!("seed corpus written to {}", out.display());
    Ok(())
}
