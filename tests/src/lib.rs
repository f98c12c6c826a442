//! Shared fixtures for the workspace integration tests: an analytic scene
//! (a textured ground plane under a sky) rendered on the CPU, so tests have
//! frames whose depth and motion are exact by construction.

use std::time::Duration;

use glam::{DVec2, DVec3};
use half::f16;
use protocol::{Camera, Frame, FrameMeta, FrameSize, Pose, Projection, WorldPoint};

/// Checkerboard radiance of the ground plane y = 0 at world (x, z): HDR, with
/// values above 1 so tone mapping matters.
pub fn ground_radiance(x: f64, z: f64) -> f32 {
    let c = ((x.floor() + z.floor()) as i64).rem_euclid(2);
    if c == 0 { 4.0 } else { 0.25 }
}

/// Sky radiance, constant.
pub const SKY: f32 = 0.5;

/// Camera of frame `index`: orbiting the origin at height 2, looking at the
/// ground ahead; optionally offset by `origin` to test huge coordinates.
pub fn camera(index: u64, fps: f64, origin: DVec3, size: FrameSize) -> Camera {
    let t = index as f64 / fps;
    let eye = origin + DVec3::new(3.0 * t.cos(), 2.0, 3.0 * t.sin() + 4.0);
    let target = origin + DVec3::new(0.0, 0.0, 0.0);
    Camera::new(
        Pose::look_at(eye, target, DVec3::Y),
        Projection::perspective(
            60f64.to_radians(),
            f64::from(size.width) / f64::from(size.height),
            0.05,
            f64::INFINITY,
        ),
    )
}

/// Camera of frame `index` spinning in place: 2 m above `origin`, looking
/// 25° down, turning about the vertical at 1 rad/s. At low frame rates the
/// turn between frames exceeds the field of view, so motion vectors grow
/// larger than the frame.
pub fn spin_camera(index: u64, fps: f64, origin: DVec3, size: FrameSize) -> Camera {
    let yaw = index as f64 / fps;
    let eye = origin + DVec3::new(0.0, 2.0, 0.0);
    let dir = DVec3::new(yaw.sin(), -25f64.to_radians().tan(), -yaw.cos());
    Camera::new(
        Pose::look_at(eye, eye + dir, DVec3::Y),
        Projection::perspective(
            60f64.to_radians(),
            f64::from(size.width) / f64::from(size.height),
            0.05,
            f64::INFINITY,
        ),
    )
}

/// A camera path of the analytic scene: frame index, fps, origin, size.
pub type CameraPath = fn(u64, f64, DVec3, FrameSize) -> Camera;

/// Renders frame `index` of the scene with the orbiting [`camera`]: color,
/// exact linear depth (`+inf` for sky) and exact motion to the previous
/// frame's camera (zero on frame 0).
pub fn render(index: u64, fps: f64, origin: DVec3, size: FrameSize) -> Frame {
    render_by(camera, index, fps, origin, size)
}

/// [`render`] along any camera path.
pub fn render_by(path: CameraPath, index: u64, fps: f64, origin: DVec3, size: FrameSize) -> Frame {
    let cam = path(index, fps, origin, size);
    let prev = path(index.saturating_sub(1), fps, origin, size);
    let dims = size.as_f64();
    let n = size.pixels() as usize;
    let (mut color, mut depth, mut motion) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for j in 0..size.height {
        for i in 0..size.width {
            let px = DVec2::new(f64::from(i) + 0.5, f64::from(j) + 0.5);
            let ray = cam.view_ray(px, dims);
            let dir = cam.pose.rotation * ray;
            // Intersect with y = origin.y: view depth d satisfies pos.y + d·dir.y = origin.y.
            let d = if dir.y < -1e-9 {
                (origin.y - cam.pose.position.y) / dir.y
            } else {
                f64::INFINITY
            };
            let (radiance, d) = match cam.unproject(px, d, dims) {
                Some(WorldPoint::Finite(p)) => (ground_radiance(p.x - origin.x, p.z - origin.z), d),
                _ => (SKY, f64::INFINITY),
            };
            let mv = cam
                .static_motion(&prev, px, d, dims, dims)
                .unwrap_or(DVec2::ZERO);
            color.push([
                f16::from_f32(radiance),
                f16::from_f32(radiance * 0.8),
                f16::from_f32(radiance * 0.6),
                f16::ONE,
            ]);
            depth.push(d as f32);
            motion.push([mv.x as f32, mv.y as f32]);
        }
    }
    Frame {
        meta: FrameMeta {
            index,
            time: index as f64 / fps,
            camera: cam,
            size,
            host_processing: Duration::from_micros(1500),
            cut: false,
        },
        color,
        depth,
        motion,
        extras: vec![],
    }
}

/// Frames of a built-in scene rendered by the server's wgpu renderer (real
/// rasterised color, depth and motion), the test data of the framegen
/// tests. `indices` are frame numbers at `fps`.
pub fn render_scene(
    name: &str,
    size: FrameSize,
    fps: f64,
    indices: impl IntoIterator<Item = u64>,
) -> Vec<Frame> {
    let scene = scene::Scene::load(&format!("builtin:{name}"))
        .unwrap_or_else(|e| panic!("scene {name}: {e}"));
    render_with(scene, None, size, fps, indices)
}

/// Like [`render_scene`] for any scene, optionally with an adaptive window.
pub fn render_with(
    scene: scene::Scene,
    window: Option<scene::render::WindowSettings>,
    size: FrameSize,
    fps: f64,
    indices: impl IntoIterator<Item = u64>,
) -> Vec<Frame> {
    let name = scene.name.clone();
    let mut renderer = scene::render::Renderer::new(scene, size, std::path::Path::new("."))
        .unwrap_or_else(|e| panic!("renderer for {name}: {e}"));
    if let Some(w) = window {
        renderer.set_window(w);
    }
    render_scene_by(&mut renderer, fps, indices)
}

/// Frames `indices` of the scene `renderer` draws, at `fps`.
pub fn render_scene_by(
    renderer: &mut scene::render::Renderer,
    fps: f64,
    indices: impl IntoIterator<Item = u64>,
) -> Vec<Frame> {
    let name = renderer.scene().name.clone();
    indices
        .into_iter()
        .map(|i| {
            renderer
                .render(i, fps)
                .unwrap_or_else(|e| panic!("render {name} frame {i}: {e}"))
        })
        .collect()
}

/// The hard-case built-in scenes (DESIGN §10), one per challenge.
pub const HARD_CASES: [&str; 10] = [
    "pan",
    "dolly",
    "crossing",
    "moving_light",
    "sky",
    "thin",
    "fast_rotation",
    "translucent",
    "cut",
    "huge",
];

/// Mean quality of one method on a 60 fps sequence fed at 30 fps: every
/// even frame of `frames` is pushed (its motion composed back to the
/// previous even frame, `framegen::decimate`), the generator makes α = 0.5,
/// and the result is compared with the odd frame it stands for (DESIGN §9).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quality {
    /// Mean PSNR (dB) on display-encoded images.
    pub psnr: f64,
    /// Mean SSIM.
    pub ssim: f64,
    /// Generated frames compared.
    pub frames: usize,
    /// Mean share of pixels that no source covered (push-pull filled).
    pub filled: f64,
    /// Mean share of pixels from the background layers.
    pub background: f64,
}

/// Runs [`Quality`] for `generator` over `frames` (consecutive frames at
/// the display rate; the first two are only fed, so history exists).
pub fn quality(generator: &mut framegen::FrameGenerator, frames: &[Frame]) -> Quality {
    let (mut psnr, mut ssim, mut filled, mut background, mut count) = (0.0, 0.0, 0.0, 0.0, 0usize);
    let fed = framegen::decimate::decimate(frames, 2);
    // Extrapolation stands in for the frame after the last fed one;
    // interpolation for the frame before it.
    let interp = generator.settings().method == framegen::Method::Interp;
    for (i, frame) in fed.iter().enumerate() {
        generator.push(frame).expect("push");
        let truth_index = if interp {
            2 * i - usize::from(i > 0)
        } else {
            2 * i + 1
        };
        let Some(truth) = frames.get(truth_index) else {
            break;
        };
        if i < 1 {
            continue;
        }
        let g = generator.generate(0.5).expect("generate");
        let size = truth.meta.size;
        let a = framegen::display_encode(size.width, size.height, &g.frame.color).expect("size");
        let b = framegen::display_encode(size.width, size.height, &truth.color).expect("size");
        psnr += framegen::psnr(&a, &b).expect("psnr").min(100.0);
        ssim += framegen::ssim(&a, &b).expect("ssim");
        let n = g.mask.len() as f64;
        filled += g.count(framegen::PixelSource::Filled) as f64 / n;
        background += g.count(framegen::PixelSource::Background) as f64 / n;
        count += 1;
    }
    let c = count.max(1) as f64;
    Quality {
        psnr: psnr / c,
        ssim: ssim / c,
        frames: count,
        filled: filled / c,
        background: background / c,
    }
}
