//! CPU reference vs wgpu, whole pipeline, on rendered hard-case scenes.

use framegen::{FrameGenerator, GpuContext, Method, Settings};
use protocol::FrameSize;

const SIZE: FrameSize = FrameSize::new(160, 96);

#[test]
fn smoke_pipeline_parity() {
    let ctx = GpuContext::new().unwrap();
    for scene in ["crossing", "pan", "dolly"] {
        let frames = tests::render_scene(scene, SIZE, 60.0, [10, 12, 14, 16]);
        for method in Method::ALL {
            let s = Settings::for_method(method);
            let mut cpu = FrameGenerator::cpu(s).unwrap();
            let mut gpu = FrameGenerator::gpu(s, ctx.clone()).unwrap();
            for f in &frames {
                let a = cpu.push(f).unwrap();
                let b = gpu.push(f).unwrap();
                assert_eq!(a, b, "{scene} {method}");
            }
            let a = cpu.generate(0.5).unwrap();
            let b = gpu.generate(0.5).unwrap();
            let mask_diff = a.mask.iter().zip(&b.mask).filter(|(x, y)| x != y).count();
            let color_diff = a
                .output
                .color
                .iter()
                .zip(&b.output.color)
                .map(|(x, y)| (0..3).map(|c| (x[c] - y[c]).abs()).fold(0f32, f32::max))
                .fold(0f32, f32::max);
            let depth_diff = a
                .output
                .depth
                .iter()
                .zip(&b.output.depth)
                .filter(|(x, y)| x != y)
                .count();
            eprintln!(
                "{scene} {method}: mask diff {mask_diff}, max color diff {color_diff}, depth diff {depth_diff}, warped {} bg {} filled {}",
                a.count(framegen::PixelSource::Warped),
                a.count(framegen::PixelSource::Background),
                a.count(framegen::PixelSource::Filled)
            );
        }
    }
}
