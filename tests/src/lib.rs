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

/// Renders frame `index` of the scene: color, exact linear depth (`+inf` for
/// sky) and exact motion to the previous frame's camera (zero on frame 0).
pub fn render(index: u64, fps: f64, origin: DVec3, size: FrameSize) -> Frame {
    let cam = camera(index, fps, origin, size);
    let prev = camera(index.saturating_sub(1), fps, origin, size);
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
    let scene = server::scene::Scene::load(&format!("builtin:{name}"))
        .unwrap_or_else(|e| panic!("scene {name}: {e}"));
    let mut renderer = server::render::Renderer::new(scene, size, std::path::Path::new("."))
        .unwrap_or_else(|e| panic!("renderer for {name}: {e}"));
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
