//! What the buffer codecs cost on rendered frames (issue 19): per buffer,
//! bytes a frame (and Mbit/s at 30 fps), encode and decode wall time, for
//! the lossless set (zstd) and the compact set (quantised depth, motion as
//! the residual over the camera), on the default scene's frame 31 after
//! frame 30. The render of the same frame is timed in the same run as the
//! yardstick (`render`).
//!
//! `cargo bench -p scene --bench codecs` (`RENDER_BENCH_SIZE=WxH` to change
//! the size from 640×360).

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use protocol::FrameSize;
use protocol::assemble::encode_frame_after;
use protocol::wire::StreamBuffer;
use protocol::{Codec, codec};
use scene::Scene;
use scene::render::Renderer;

fn size() -> FrameSize {
    std::env::var("RENDER_BENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(FrameSize::new(640, 360))
}

fn codecs(c: &mut Criterion) {
    // As the binaries do: the encoders' frame-sized buffers stay in the
    // heap from one frame to the next.
    protocol::memory::retain_freed_memory();
    let size = size();
    let scene = Scene::load("builtin:default").expect("built-in scene");
    let mut r = Renderer::new(scene, size, Path::new(".")).expect("renderer");
    let previous = r.render(30, 30.0).expect("frame").meta;
    let frame = r.render(31, 30.0).expect("frame");
    let mut group = c.benchmark_group(format!("codecs_{}x{}", size.width, size.height));
    group.sample_size(10);
    group.bench_function("render", |b| b.iter(|| r.render(31, 30.0).expect("frame")));
    let level = codec::DEFAULT_ZSTD_LEVEL;
    for (name, set) in [
        ("lossless", StreamBuffer::default_set(Codec::Raw)),
        ("compact", StreamBuffer::compact_set(Codec::Raw)),
    ] {
        let encoded = encode_frame_after(&frame, Some(&previous), &set, level).expect("encodes");
        for (desc, payload) in encoded.header.buffers.iter().zip(&encoded.payloads) {
            let bytes = payload.data.len();
            println!(
                "{name:>8} {:?} as {:?}: {bytes} bytes a frame, {:.1} Mbit/s at 30 fps",
                desc.kind,
                desc.codec,
                bytes as f64 * 8.0 * 30.0 / 1e6
            );
        }
        // Colour is raw in both (a copy): what differs is depth and motion.
        group.bench_function(format!("{name}_encode"), |b| {
            b.iter(|| encode_frame_after(&frame, Some(&previous), &set, level).expect("encodes"))
        });
        let encoded = encode_frame_after(&frame, Some(&previous), &set, level).expect("encodes");
        group.bench_function(format!("{name}_decode"), |b| {
            b.iter(|| encoded.decode().expect("decodes"))
        });
    }
    group.finish();
}

criterion_group!(benches, codecs);
criterion_main!(benches);
