//! The profiled wgpu backend's pass times: wall time always, GPU
//! timestamps where asked for and offered; a software rasteriser is never
//! timed by its (unreliable) timestamps unless forced.

use framegen::{FrameGenerator, GpuBackend, GpuContext, Method, Pass, PassClock, Settings};
use protocol::FrameSize;

#[test]
fn profiled_passes_are_timed_on_either_clock() {
    let ctx = GpuContext::new().expect("a wgpu adapter (lavapipe in CI)");
    if ctx.adapter_info.device_type == wgpu::DeviceType::Cpu {
        assert_eq!(PassClock::preferred(&ctx), PassClock::Wall);
    }
    let frames = tests::render_scene("crossing", FrameSize::new(64, 36), 30.0, 10..13);
    let run = |backend: GpuBackend| {
        let mut g =
            FrameGenerator::with_backend(Settings::for_method(Method::Gffe), Box::new(backend))
                .unwrap();
        for f in &frames {
            g.push(f).unwrap();
        }
        g.generate(0.5).unwrap();
        g.timings()
    };
    let wall = run(GpuBackend::profiled_with(ctx.clone(), PassClock::Wall).unwrap());
    let passes: Vec<Pass> = wall.iter().map(|t| t.pass).collect();
    for p in [Pass::History, Pass::Background, Pass::Warp, Pass::Holes] {
        assert!(passes.contains(&p), "{p:?} missing from {passes:?}");
    }
    assert!(wall.iter().all(|t| t.gpu.is_none() && !t.time.is_zero()));
    match GpuBackend::profiled_with(ctx.clone(), PassClock::Timestamps) {
        Ok(backend) => {
            let ts = run(backend);
            eprintln!("timestamps: {ts:?}");
            // Every recorded pass (upload and read-back are host work) has
            // a GPU time beside its wall time.
            for t in &ts {
                let host = matches!(t.pass, Pass::Upload | Pass::Readback);
                assert_eq!(t.gpu.is_some(), !host, "{t:?}");
                // GPU time lies inside the waited span (scaled by the
                // timestamp period; a wrong scale is off by orders).
                assert!(t.gpu.is_none_or(|g| g <= t.time * 2), "{t:?}");
            }
        }
        Err((_, e)) => {
            eprintln!("no timestamps: {e}");
            assert!(
                e.to_string().contains("TIMESTAMP_QUERY"),
                "the refusal names the features: {e}"
            );
        }
    }
}
