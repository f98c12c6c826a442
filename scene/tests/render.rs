//! The renderer on lavapipe: effects gating, determinism, motion vectors
//! against depth + camera reprojection (static pixels) and against the
//! objects' own motion (moving pixels), and a recorded dump read back.

use std::path::Path;

use glam::{DVec2, DVec3};
use protocol::dump::{DumpReader, DumpWriter, Manifest};
use protocol::{BufferKind, Frame, FrameSize, WorldPoint};
use scene::render::{Pass, Renderer, ViewerPoses, plan};
use scene::{Scene, builtin};

const SIZE: FrameSize = FrameSize::new(320, 180);

fn renderer(name: &str) -> Renderer {
    let scene = Scene::load(&format!("builtin:{name}")).unwrap();
    Renderer::new(scene, SIZE, Path::new(".")).unwrap()
}

/// Pixels whose red differs by more than `by` between two frames.
fn red_changed(a: &Frame, b: &Frame, by: f32) -> usize {
    a.color
        .iter()
        .zip(&b.color)
        .filter(|(p, q)| (p[0].to_f32() - q[0].to_f32()).abs() > by)
        .count()
}

fn pixel(i: usize) -> DVec2 {
    let w = SIZE.width as usize;
    DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5)
}

fn is_animated(r: &Renderer, id: u32) -> bool {
    id.checked_sub(1)
        .map(|i| r.instances()[i as usize])
        .is_some_and(|inst| !r.scene().objects[inst.object].animation.is_empty())
}

#[test]
fn passes_follow_the_declared_effects() {
    for name in builtin::names() {
        let r = renderer(name);
        let scene = r.scene();
        assert_eq!(r.passes(), plan(scene).as_slice(), "{name}");
        assert_eq!(
            r.built_pipelines(),
            plan(scene),
            "{name}: only planned pipelines are built"
        );
        let has = |p| r.passes().contains(&p);
        assert_eq!(
            has(Pass::Shadow),
            scene.has(scene::Effect::Shadows),
            "{name}"
        );
        assert_eq!(
            has(Pass::Translucent),
            scene.has(scene::Effect::Translucency),
            "{name}"
        );
        assert!(has(Pass::Opaque) && has(Pass::Background));
    }
    assert!(!plan(&Scene::load("builtin:sky").unwrap()).contains(&Pass::Shadow));
    assert!(!plan(&Scene::load("builtin:crossing").unwrap()).contains(&Pass::Translucent));
}

const BASE: &str = r#"(
    name: "probe",
    description: "effect probe",
    effects: [EFFECTS],
    camera: (fov_y_deg: 50, path: Static(eye: (0, 3, 6), target: (0, 0.5, 0))),
    materials: {
        "ground": (albedo: (0.6, 0.6, 0.6)),
        "shiny": (albedo: (0.5, 0.2, 0.2), roughness: 0.1, specular: 1.0),
    },
    objects: [
        (name: "ground", mesh: Plane(size: (20, 20)), material: "ground"),
        (name: "ball", mesh: Sphere(radius: 1), material: "shiny", transform: (position: (0, 1, 0))),
    ],
    lights: [(kind: Directional(direction: (-0.5, -1, -0.3)), intensity: 3.0)],
)"#;

fn probe(effects: &str) -> Frame {
    let scene = Scene::from_ron(&BASE.replace("EFFECTS", effects), "probe").unwrap();
    Renderer::new(scene, SIZE, Path::new("."))
        .unwrap()
        .render(0, 30.0)
        .unwrap()
}

#[test]
fn adding_an_effect_changes_the_image() {
    let plain = probe("");
    let differs =
        |a: &Frame, b: &Frame| a.color.iter().zip(&b.color).filter(|(p, q)| p != q).count();
    for effect in ["shadows", "specular", "sky"] {
        let with = probe(effect);
        let n = differs(&plain, &with);
        assert!(n > 100, "{effect} changed only {n} pixels");
        // Geometry outputs do not depend on shading effects.
        assert_eq!(plain.depth, with.depth, "{effect}");
    }
}

#[test]
fn rendering_is_deterministic() {
    let mut a = renderer("default");
    let f1 = a.render(7, 30.0).unwrap();
    a.render(3, 30.0).unwrap();
    let f2 = a.render(7, 30.0).unwrap();
    let f3 = renderer("default").render(7, 30.0).unwrap();
    for f in [&f2, &f3] {
        assert_eq!(f1.color, f.color);
        assert_eq!(f1.depth, f.depth);
        assert_eq!(f1.motion, f.motion);
        assert_eq!(f1.extras, f.extras);
        assert_eq!(f1.meta.camera, f.meta.camera);
    }
}

/// Max and mean |GPU motion − expected| over pixels where `expected` is
/// defined.
fn compare(frame: &Frame, mut expected: impl FnMut(usize) -> Option<DVec2>) -> (f64, f64, usize) {
    let (mut max, mut sum, mut n) = (0.0f64, 0.0, 0);
    for i in 0..frame.motion.len() {
        let Some(want) = expected(i) else { continue };
        let got = DVec2::new(f64::from(frame.motion[i][0]), f64::from(frame.motion[i][1]));
        let err = (got - want).length();
        max = max.max(err);
        sum += err;
        n += 1;
    }
    (max, sum / n.max(1) as f64, n)
}

#[test]
fn static_motion_matches_depth_and_camera_reprojection() {
    for name in ["pan", "dolly", "sky", "huge", "thin"] {
        let mut r = renderer(name);
        for fps in [30.0, 60.0] {
            let index = 17;
            let frame = r.render(index, fps).unwrap();
            let ids = r.last_ids().to_vec();
            let prev_cam = r.camera(&r.scene().evaluate((index - 1) as f64 / fps));
            let cur = frame.meta.camera;
            let dims = SIZE.as_f64();
            let (max, mean, n) = compare(&frame, |i| {
                if is_animated(&r, ids[i]) {
                    return None;
                }
                cur.static_motion(&prev_cam, pixel(i), f64::from(frame.depth[i]), dims, dims)
            });
            eprintln!(
                "{name} @ {fps} fps: static motion error max {max:.5} px, mean {mean:.6} px over {n} pixels"
            );
            assert!(
                n > (SIZE.pixels() as usize) / 2,
                "{name}: only {n} static pixels"
            );
            assert!(
                max < 0.05,
                "{name} @ {fps} fps: max error {max:.4} px (mean {mean:.5})"
            );
            let sky = frame.depth.iter().filter(|d| d.is_infinite()).count();
            if name == "sky" {
                assert!(sky > 1000, "the sky scene shows sky");
            }
        }
    }
}

/// The viewer's cameras (issue 20): given the scene's own path, a posed
/// render is the scripted one bit for bit; given a camera turning away from
/// the path, the frame shows that camera and its static motion vectors
/// lead to the previous viewer camera through depth.
#[test]
fn a_viewer_camera_renders_like_the_path_it_replaces() {
    let fps = 30.0;
    let index = 11u64;
    let time = |k: u64| k as f64 / fps;
    let mut r = renderer("default");
    let path = |r: &Renderer, k: u64| r.camera(&r.scene().evaluate(time(k))).pose;
    let poses = ViewerPoses {
        now: path(&r, index),
        prev: path(&r, index - 1),
        before: path(&r, index - 2),
    };
    let scripted = r.render(index, fps).unwrap();
    let posed = r
        .render_posed(index, time(index), time(index - 1), &poses)
        .unwrap();
    let timeless = |f: &Frame| protocol::FrameMeta {
        host_processing: std::time::Duration::ZERO,
        ..f.meta
    };
    assert_eq!(timeless(&scripted), timeless(&posed));
    assert_eq!(scripted.color, posed.color);
    assert_eq!(scripted.depth, posed.depth);
    assert_eq!(scripted.motion, posed.motion);

    // A viewer turning 3° a frame about the vertical, 1 m to the side.
    let turn = |k: u64| {
        let p = path(&r, index);
        protocol::Pose::new(
            p.position + DVec3::new(1.0, 0.0, 0.0),
            glam::DQuat::from_rotation_y((k as f64 * 3.0).to_radians()) * p.rotation,
        )
    };
    let viewer = ViewerPoses {
        now: turn(2),
        prev: turn(1),
        before: turn(0),
    };
    let frame = r
        .render_posed(index, time(index), time(index - 1), &viewer)
        .unwrap();
    assert_eq!(frame.meta.camera.pose, viewer.now);
    assert!(!frame.meta.cut);
    assert_ne!(frame.color, scripted.color);
    let ids = r.last_ids().to_vec();
    let mut prev_cam = frame.meta.camera;
    prev_cam.pose = viewer.prev;
    let dims = SIZE.as_f64();
    let (max, mean, n) = compare(&frame, |i| {
        if is_animated(&r, ids[i]) {
            return None;
        }
        frame
            .meta
            .camera
            .static_motion(&prev_cam, pixel(i), f64::from(frame.depth[i]), dims, dims)
    });
    assert!(n > (SIZE.pixels() as usize) / 2, "only {n} static pixels");
    assert!(
        max < 0.05,
        "static motion off by {max:.4} px (mean {mean:.5})"
    );
}

#[test]
fn moving_objects_match_their_analytic_motion() {
    for name in ["crossing", "default"] {
        let mut r = renderer(name);
        let fps = 30.0;
        let index = 20;
        let frame = r.render(index, fps).unwrap();
        let ids = r.last_ids().to_vec();
        let t = index as f64 / fps;
        let (now, before) = (r.scene().evaluate(t), r.scene().evaluate(t - 1.0 / fps));
        let prev_cam = r.camera(&before);
        let cur = frame.meta.camera;
        let dims = SIZE.as_f64();
        let (max, mean, n) = compare(&frame, |i| {
            if !is_animated(&r, ids[i]) {
                return None;
            }
            let inst = (ids[i] - 1) as usize;
            let Some(WorldPoint::Finite(p)) =
                cur.unproject(pixel(i), f64::from(frame.depth[i]), dims)
            else {
                return None;
            };
            // Carry the surface point with its object back to t − Δt.
            let local = now.models[inst].inverse().transform_point3(p);
            let then = before.models[inst].transform_point3(local);
            Some(prev_cam.project(WorldPoint::Finite(then), dims)?.pixel - pixel(i))
        });
        eprintln!("{name}: object motion error max {max:.5} px, mean {mean:.6} px over {n} pixels");
        assert!(n > 200, "{name}: only {n} moving pixels");
        assert!(
            max < 0.05,
            "{name}: max error {max:.4} px (mean {mean:.5}) over {n} pixels"
        );
        // The dynamic mask marks exactly those pixels.
        let mask = &frame
            .extras
            .iter()
            .find(|e| e.kind == BufferKind::Mask)
            .unwrap()
            .data;
        let marked = mask.iter().filter(|&&m| m == 255).count();
        assert_eq!(
            marked,
            ids.iter().filter(|&&id| is_animated(&r, id)).count()
        );
        // And they do move.
        let moving = (0..ids.len())
            .filter(|&i| is_animated(&r, ids[i]))
            .filter(|&i| frame.motion[i][0].hypot(frame.motion[i][1]) > 0.1)
            .count();
        assert!(moving > n / 2, "{name}: moving objects should move");
    }
}

#[test]
fn a_cut_frame_is_flagged_and_has_no_motion() {
    let mut r = renderer("cut");
    let fps = 30.0;
    // The first shot ends at 1.5 s = frame 45.
    let before = r.render(44, fps).unwrap();
    let at = r.render(45, fps).unwrap();
    assert!(!before.meta.cut && at.meta.cut);
    assert!(
        at.motion
            .iter()
            .all(|m| m[0].abs() < 1e-3 && m[1].abs() < 1e-3)
    );
    assert!(before.motion.iter().any(|m| m[0].abs() > 0.01));
}

#[test]
fn fast_rotation_moves_over_100_pixels_per_frame_at_720p() {
    // Motion scales with width: 320 px here, so 100 px at 1280 is 25 px.
    let mut r = renderer("fast_rotation");
    let frame = r.render(10, 30.0).unwrap();
    let median = {
        let mut m: Vec<f32> = frame.motion.iter().map(|m| m[0].hypot(m[1])).collect();
        m.sort_by(f32::total_cmp);
        m[m.len() / 2]
    };
    assert!(
        median * 1280.0 / SIZE.width as f32 > 100.0,
        "median {median} px at 320 wide"
    );
}

#[test]
fn huge_coordinates_render_like_the_origin() {
    // The same layout at the origin and at 1e5 gives the same depth.
    let huge = Scene::load("builtin:huge").unwrap();
    let mut near = huge.clone();
    near.origin = [0.0; 3];
    let a = Renderer::new(huge, SIZE, Path::new("."))
        .unwrap()
        .render(5, 30.0)
        .unwrap();
    let b = Renderer::new(near, SIZE, Path::new("."))
        .unwrap()
        .render(5, 30.0)
        .unwrap();
    let max = a
        .depth
        .iter()
        .zip(&b.depth)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| (x - y).abs() / y)
        .fold(0.0f32, f32::max);
    assert!(max < 1e-3, "relative depth difference {max}");
    let pos = a.meta.camera.pose.position - b.meta.camera.pose.position;
    assert!((pos - DVec3::new(1e5, 0.0, -1e5)).length() < 1e-6);
}

#[test]
fn a_recorded_dump_reads_back_identically() {
    let dir = tempfile::tempdir().unwrap();
    let mut r = renderer("crossing");
    let mut w = DumpWriter::create(dir.path(), Manifest::new(30.0, SIZE, "test")).unwrap();
    let frames: Vec<Frame> = (0..3).map(|k| r.render(k, 30.0).unwrap()).collect();
    for f in &frames {
        w.write_frame(f).unwrap();
    }
    w.finish().unwrap();
    let back: Vec<Frame> = DumpReader::open(dir.path())
        .unwrap()
        .frames()
        .map(Result::unwrap)
        .collect();
    assert_eq!(back, frames);
}

fn windowed(name: &str, mode: protocol::wire::WindowMode) -> Renderer {
    let mut r = renderer(name);
    r.set_window(scene::render::WindowSettings {
        mode,
        ..Default::default()
    });
    r
}

#[test]
fn the_adaptive_window_widens_towards_the_turn_and_crops_to_the_plain_frame() {
    use protocol::wire::WindowMode;
    let plain = renderer("pan").render(10, 30.0).unwrap();
    let mut r = windowed("pan", WindowMode::KeepDensity);
    let prev = r.render(9, 30.0).unwrap();
    let wide = r.render(10, 30.0).unwrap();
    let w = wide.meta.camera.window;
    // The pan turns left (1° per frame): the left side grows; the pitched
    // view's footprint also shifts a little vertically. Display density.
    assert!(
        w.u0 < -1.02 && w.u1 == 1.0 && w.v0 > -1.05 && w.v1 < 1.05,
        "{w:?}"
    );
    assert!(wide.meta.size.width > SIZE.width + 4);
    let (x0, y0, _, _) = w.display_rect(wide.meta.size.as_f64());
    let (x0, y0) = (x0.round() as u32, y0.round() as u32);
    let mut same_color = 0;
    for y in 0..SIZE.height {
        for x in 0..SIZE.width {
            let a = plain.index(x, y);
            let b = wide.index(x + x0, y + y0);
            let (da, db) = (plain.depth[a], wide.depth[b]);
            assert!(
                da == db || (da - db).abs() <= 1e-4 * da,
                "depth at {x},{y}: {da} vs {db}"
            );
            same_color += usize::from(plain.color[a] == wide.color[b]);
        }
    }
    assert!(
        same_color as f64 > 0.99 * SIZE.pixels() as f64,
        "{same_color} equal colors"
    );
    // Motion lands in the previous frame's own (widened) pixel grid.
    let (cur, prev_cam) = (wide.meta.camera, prev.meta.camera);
    let (dims, prev_dims) = (wide.meta.size.as_f64(), prev.meta.size.as_f64());
    let (max, _, n) = compare(&wide, |i| {
        let w = wide.meta.size.width as usize;
        let px = DVec2::new((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
        cur.static_motion(&prev_cam, px, f64::from(wide.depth[i]), dims, prev_dims)
    });
    assert!(n > 50_000 && max < 0.05, "max {max} over {n}");
}

#[test]
fn keep_size_widens_the_window_at_a_fixed_size() {
    use protocol::wire::WindowMode;
    let mut r = windowed("pan", WindowMode::KeepSize);
    let f = r.render(10, 30.0).unwrap();
    assert_eq!(f.meta.size, SIZE);
    assert!(f.meta.camera.window.u0 < -1.02);
    // A still camera keeps the plain window.
    let mut still = windowed("crossing", WindowMode::KeepDensity);
    assert!(still.render(10, 30.0).unwrap().meta.camera.window.is_full());
}

#[test]
fn a_moving_light_moves_shadows_on_static_geometry() {
    let mut r = renderer("moving_light");
    let a = r.render(0, 30.0).unwrap();
    let b = r.render(15, 30.0).unwrap();
    // Nothing geometric moves: same depth, zero motion.
    assert_eq!(a.depth, b.depth);
    assert!(
        b.motion
            .iter()
            .all(|m| m[0].abs() < 1e-4 && m[1].abs() < 1e-4)
    );
    // But the shading does, over a large part of the image.
    let changed = red_changed(&a, &b, 0.05);
    assert!(
        changed > (SIZE.pixels() / 10) as usize,
        "only {changed} pixels changed"
    );
}

/// The shadow map follows the frame (2048² at 1280×720, at least 1024²),
/// a caller may pin it, and another map changes only the shadows: colour
/// where they fall, never depth or motion.
#[test]
fn the_shadow_map_follows_the_frame_and_can_be_pinned() {
    assert_eq!(renderer("sky").shadow_map(), None);
    let mut r = renderer("spinning_shadow");
    assert_eq!(
        r.shadow_map(),
        Some(scene::render::shadow_map_side(SIZE)),
        "the frame's own density"
    );
    assert_eq!(r.shadow_map(), Some(1024));
    let coarse = r.render(12, 30.0).unwrap();
    r.set_shadow_map(2048).unwrap();
    assert_eq!(r.shadow_map(), Some(2048));
    let sharp = r.render(12, 30.0).unwrap();
    assert_eq!(coarse.depth, sharp.depth);
    assert_eq!(coarse.motion, sharp.motion);
    let changed = red_changed(&coarse, &sharp, 0.02);
    // The shadow's penumbra, a small part of the frame.
    assert!(
        changed > 20 && changed < (SIZE.pixels() / 10) as usize,
        "{changed} pixels changed"
    );
    // Pinned to nothing: clamped to one texel, and still renders.
    r.set_shadow_map(0).unwrap();
    assert_eq!(r.shadow_map(), Some(1));
    let none = r.render(12, 30.0).unwrap();
    assert_eq!(none.depth, sharp.depth);
    assert!(none.color.iter().flatten().all(|c| c.to_f32().is_finite()));
}

/// The renderer on wgpu's OpenGL backend (what a machine without Mesa's
/// Vulkan driver has) against Vulkan, every built-in scene, a moving frame
/// each. Depth and motion are rendered as their `f32` bit patterns into
/// integer targets on both, so OpenGL needs no float render target.
///
/// Tolerances: both are Mesa's software rasterisers (llvmpipe through
/// OpenGL, lavapipe through Vulkan) with the same coverage rules, but the
/// shaders reach them through different front ends (GLSL vs SPIR-V), so
/// values may differ in the last bits: depth 1e-5 relative, motion 1e-3 px,
/// colour 1e-2 relative (HDR, f16); a pixel on a silhouette may flip, so
/// at most 0.1 % of pixels may differ beyond that (measured: at most 6 of
/// 57 600, on `dolly`'s motion).
#[test]
fn opengl_renders_what_vulkan_renders() {
    let open = |backends| {
        let adapter = gpu_device::adapter_on(backends).expect("an adapter on this backend");
        scene::render::gpu::on_adapter(&adapter).expect("the renderer's formats")
    };
    for name in builtin::names() {
        let render = |backends| {
            let scene = Scene::load(&format!("builtin:{name}")).unwrap();
            let mut r = Renderer::on(open(backends), scene, SIZE, Path::new(".")).unwrap();
            r.render(20, 30.0).unwrap()
        };
        let (gl, vk) = (render(wgpu::Backends::GL), render(wgpu::Backends::VULKAN));
        let close =
            |a: f32, b: f32, rel: f32| a == b || (a - b).abs() <= rel * a.abs().max(b.abs());
        let n = gl.depth.len();
        let depth = (0..n)
            .filter(|&i| !close(gl.depth[i], vk.depth[i], 1e-5))
            .count();
        let motion = (0..n)
            .filter(|&i| (0..2).any(|c| (gl.motion[i][c] - vk.motion[i][c]).abs() > 1e-3))
            .count();
        let color = (0..n)
            .filter(|&i| {
                (0..3).any(|c| !close(gl.color[i][c].to_f32(), vk.color[i][c].to_f32(), 1e-2))
            })
            .count();
        eprintln!("{name}: of {n} pixels, depth {depth}, motion {motion}, colour {color} differ");
        let bound = n / 1000;
        assert!(
            depth <= bound && motion <= bound && color <= bound,
            "{name}"
        );
    }
}

#[test]
fn a_frame_with_earlier_shading_keeps_its_geometry_and_takes_the_earlier_light() {
    let fps = 30.0;
    let time = |k: u64| k as f64 / fps;
    let times = |k: u64| [time(k), time(k - 1), time(k - 2)];
    // A light circling static blocks under a static camera: the frame at
    // 12 with frame 6's shading is frame 6.
    let mut r = renderer("moving_light");
    let now = r.render(12, fps).unwrap();
    let earlier = r.render(6, fps).unwrap();
    let shaded = r.render_shaded_at(12, times(12), time(6)).unwrap();
    assert_ne!(now.color, earlier.color, "the light moved");
    assert_eq!(shaded.color, earlier.color);
    assert_eq!(shaded.depth, now.depth);
    assert_eq!(shaded.meta.time, now.meta.time);
    // Its own time's shading is the plain render.
    let same = r.render_shaded_at(12, times(12), time(12)).unwrap();
    assert_eq!(same.color, now.color);
    // A spinning shadow caster under a moving camera: the caster is drawn
    // where it is now (depth, motion), its shadow where it was.
    let mut r = renderer("spinning_shadow");
    let now = r.render(12, fps).unwrap();
    let shaded = r.render_shaded_at(12, times(12), time(9)).unwrap();
    assert_eq!(shaded.depth, now.depth);
    assert_eq!(shaded.motion, now.motion);
    assert_eq!(shaded.meta.camera, now.meta.camera);
    let differ = (now.color.iter().zip(&shaded.color))
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        differ > 100 && differ < SIZE.pixels() as usize / 4,
        "{differ} pixels changed: the shadow, not the frame"
    );
}
