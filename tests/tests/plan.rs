//! The generation plan (issue 17) is what the generator runs: for every
//! built-in scene, with the effects its stream announces, each method's
//! plan lists exactly the passes the backend ran for a frame that continues
//! its history, in their order — on the CPU reference and on wgpu (timed
//! per pass) — and the plan follows the effects: shading correction only
//! where shading moves, trajectories only where objects move. As the
//! renderer's gating test checks its passes against its plan.

use framegen::pipeline::Pass;
use framegen::{FrameGenerator, GpuContext, Method, Settings};
use protocol::FrameSize;

const SIZE: FrameSize = FrameSize::new(64, 36);

/// The passes of the last push and generation, upload, packing and
/// read-back aside (they move data, every plan has them on the GPU).
fn ran(g: &FrameGenerator) -> Vec<Pass> {
    g.timings()
        .iter()
        .map(|t| t.pass)
        .filter(|p| !matches!(p, Pass::Upload | Pass::Pack | Pass::Readback))
        .collect()
}

#[test]
fn every_builtin_scene_runs_its_plan() {
    let ctx = GpuContext::new().expect("a wgpu adapter (lavapipe in CI)");
    for name in scene::builtin::names() {
        let effects = scene::Scene::load(&format!("builtin:{name}"))
            .unwrap_or_else(|e| panic!("{name}: {e}"))
            .stream_effects();
        // Three 30 fps frames from 60 fps renders: the last continues the
        // history (the `cut` scene cuts later).
        let all = tests::render_scene(name, SIZE, 60.0, 0..6);
        let frames = framegen::decimate::decimate(&all, 2);
        for method in Method::ALL {
            let settings = Settings {
                effects,
                ..Settings::for_method(method)
            };
            let plan = settings.plan();
            let gffe = method == Method::Gffe;
            assert_eq!(
                plan.shading,
                gffe && effects.moving_shading,
                "{name}: {plan}"
            );
            if gffe {
                let k = if effects.dynamic_objects {
                    settings.history
                } else {
                    1
                };
                assert_eq!(plan.history, k, "{name}: {plan}");
            }
            let planned: Vec<Pass> = plan.passes().collect();
            let mut cpu = FrameGenerator::cpu(settings).unwrap();
            let mut gpu = FrameGenerator::gpu(settings, ctx.clone()).unwrap();
            gpu.set_profiling(true);
            for g in [&mut cpu, &mut gpu] {
                for f in &frames {
                    g.push(f).unwrap();
                }
                g.generate(0.5).unwrap();
                assert_eq!(ran(g), planned, "{name}, {} on {}", plan, g.backend_name());
            }
        }
    }
}
