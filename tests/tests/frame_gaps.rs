//! Frame gaps (issue 16 §6): a rendered frame that never arrives. The
//! next frame's motion vectors point to the missing one, so the generator
//! restarts the trajectories (every pixel static, no velocity) but keeps
//! the background layers, which are positions and need only the cameras;
//! eq. 2 and the generated frames' times count α in render intervals of
//! the stream, measured with the frames' real time stamps; interpolation
//! has no pair across the gap. Checked on both backends against the same
//! stream without the gap, and against the gap taken for a continuation
//! (the frame renumbered: its motion then meets the history of the frame
//! before the missing one, the behaviour before gaps were detected).

use framegen::{FrameGenerator, GpuContext, Method, PixelSource, PushOutcome, Settings};
use protocol::{Frame, FrameSize};

const SIZE: FrameSize = FrameSize::new(160, 90);
const FPS: f64 = 30.0;

fn psnr(a: &Frame, b: &Frame) -> f64 {
    let s = a.meta.size;
    let x = framegen::display_encode(s.width, s.height, &a.color).unwrap();
    let y = framegen::display_encode(s.width, s.height, &b.color).unwrap();
    framegen::psnr(&x, &y).unwrap()
}

/// A CPU and a wgpu generator for `method`.
fn both(method: Method) -> [FrameGenerator; 2] {
    let s = Settings::for_method(method);
    [
        FrameGenerator::cpu(s).unwrap(),
        FrameGenerator::gpu(s, GpuContext::new().unwrap()).unwrap(),
    ]
}

/// Pushes the first `n` of `frames`.
fn push_all(g: &mut FrameGenerator, frames: &[Frame], n: usize) -> Vec<PushOutcome> {
    frames.iter().take(n).map(|f| g.push(f).unwrap()).collect()
}

/// Frames 20..=25 at 30 fps; the stream with frame 23 missing; the same
/// taken for a continuation (24 and 25 renumbered 23 and 24).
fn streams(scene: &str) -> (Vec<Frame>, Vec<Frame>, Vec<Frame>) {
    let all = tests::render_scene(scene, SIZE, FPS, 20..=25);
    let gap: Vec<Frame> = all.iter().filter(|f| f.meta.index != 23).cloned().collect();
    let mut renumbered = gap.clone();
    for f in &mut renumbered[3..] {
        f.meta.index -= 1;
    }
    (all, gap, renumbered)
}

#[test]
fn a_missing_frame_restarts_the_tracks_and_keeps_camera_and_background() {
    for scene in ["default", "crossing", "pan", "fast_rotation"] {
        let (all, gap, renumbered) = streams(scene);
        // The skipped frame half-way after frame 24.
        let truth = tests::render_scene(scene, SIZE, 2.0 * FPS, [49]).remove(0);
        let [cpu_full, gpu_full] = both(Method::Gffe);
        let [cpu_gap, gpu_gap] = both(Method::Gffe);
        let [cpu_bug, gpu_bug] = both(Method::Gffe);
        let runs = [
            ("cpu", cpu_full, cpu_gap, cpu_bug),
            ("wgpu", gpu_full, gpu_gap, gpu_bug),
        ];
        let mut sources = Vec::new();
        for (backend, mut full, mut g, mut bug) in runs {
            let full_out = push_all(&mut full, &all, 5);
            let gap_out = push_all(&mut g, &gap, 4);
            let bug_out = push_all(&mut bug, &renumbered, 4);
            let [a, b, c] = [&mut full, &mut g, &mut bug].map(|g| g.generate(0.5).unwrap());
            let [pa, pb, pc] = [&a, &b, &c].map(|g| psnr(&g.frame, &truth));
            let at = format!("{scene} {backend}");
            eprintln!(
                "{at}: after 24 full {:?} gap {:?} renumbered {:?}; PSNR {pa:.2} / {pb:.2} / {pc:.2} dB",
                full_out[4], gap_out[3], bug_out[3]
            );
            // The gap frame continues (no restart) with no static test.
            assert_eq!(gap_out[3], PushOutcome::Continued { dynamic: 0 }, "{at}");
            // Half a render interval after frame 24, not a whole one.
            let t = b.frame.meta.time * FPS;
            assert!((t - 24.5).abs() < 1e-9, "{at}: generated at frame {t}");
            // eq. 2 over the double step: the camera of the gapless run,
            // to within a few per cent of a step on a curved path.
            let (qa, qb) = (a.frame.meta.camera.pose, b.frame.meta.camera.pose);
            let step =
                (all[4].meta.camera.pose.position - all[3].meta.camera.pose.position).length();
            let off = (qa.position - qb.position).length();
            assert!(
                off <= 0.05 * step + 1e-9,
                "{at}: camera {off} off, step {step}"
            );
            assert!(qa.rotation.angle_between(qb.rotation) < 1e-3, "{at}");
            // Better than taking the gap for a continuation (false dynamic
            // pixels or a false cut); as good as without the gap where
            // nothing but the camera moves, and within what the restarted
            // object tracks cost where objects move (measured: crossing
            // 30.56 → 28.64 dB, default 27.38 → 27.46, pan and
            // fast_rotation equal; taken for a continuation 28.37, 26.74,
            // 47.06, 11.76).
            assert!(pb > pc, "{at}: {pb:.2} dB, continuation {pc:.2}");
            assert!(pb > pa - 2.5, "{at}: {pb:.2} dB, without the gap {pa:.2}");
            if matches!(scene, "pan" | "fast_rotation") {
                assert!(pb > pa - 0.1, "{at}: {pb:.2} dB, without the gap {pa:.2}");
            }
            // The frame after the gap is tracked as without it.
            assert_eq!(
                full.push(&all[5]).unwrap(),
                g.push(&gap[4]).unwrap(),
                "{at}"
            );
            let kinds = [
                PixelSource::Warped,
                PixelSource::Background,
                PixelSource::Filled,
            ];
            sources.push([&a, &b, &c].map(|g| kinds.map(|k| g.count(k))));
        }
        // Each generated pixel comes from the same source on both
        // backends, by count (measured: the same counts; after the gap
        // 1 background pixel in `default`, 6 in `fast_rotation`, which
        // the CPU's background fill finds among the whole background the
        // gap carried over).
        assert_eq!(sources[0], sources[1], "{scene}: cpu, wgpu");
    }
}

#[test]
fn interpolation_has_no_pair_across_a_gap() {
    let (_, gap, _) = streams("crossing");
    for mut g in both(Method::Interp) {
        let name = g.backend_name();
        push_all(&mut g, &gap, 4);
        // Frames 22 and 24 are no pair (24's motion points to 23): the
        // current frame is shown as it is.
        let out = g.generate(0.5).unwrap();
        assert_eq!(out.count(PixelSource::Copied), out.mask.len(), "{name}");
        assert_eq!(out.frame.color, gap[3].color, "{name}");
        // 24 and 25 are.
        g.push(&gap[4]).unwrap();
        let out = g.generate(0.5).unwrap();
        assert!(
            out.count(PixelSource::Warped) > out.mask.len() / 2,
            "{name}"
        );
    }
}
