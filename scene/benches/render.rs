//! Wall time of one rendered frame (submit + GPU work + readback of color,
//! depth, motion and ids) per built-in scene at 1280×720. On lavapipe GPU
//! timestamps are unreliable, so this is wall time, as the DESIGN asks.
//!
//! `cargo bench -p scene --bench render` (set `RENDER_BENCH_SIZE=WxH` to
//! change the size, `RENDER_BENCH_SHADOW_MAP=TEXELS` to pin the shadow
//! map's side instead of the frame size's).

use std::path::Path;

use criterion::{Criterion, criterion_group, criterion_main};
use protocol::FrameSize;
use scene::render::Renderer;
use scene::{Scene, builtin};

fn size() -> FrameSize {
    std::env::var("RENDER_BENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(FrameSize::new(1280, 720))
}

fn shadow_map() -> Option<u32> {
    std::env::var("RENDER_BENCH_SHADOW_MAP")
        .ok()
        .and_then(|s| s.parse().ok())
}

fn render(c: &mut Criterion) {
    let size = size();
    let mut group = c.benchmark_group(format!("render_{}x{}", size.width, size.height));
    group.sample_size(10);
    for name in builtin::names() {
        let scene = Scene::load(&format!("builtin:{name}")).expect("built-in scene");
        let mut r = Renderer::new(scene, size, Path::new(".")).expect("renderer");
        if let Some(side) = shadow_map() {
            r.set_shadow_map(side).expect("shadow map");
        }
        let mut k = 30;
        group.bench_function(name, |b| {
            b.iter(|| {
                k += 1;
                r.render(k, 30.0).expect("frame")
            })
        });
    }
    group.finish();
}

criterion_group!(benches, render);
criterion_main!(benches);
