//! CPU side of the shader uniforms (`common.wgsl`), built in `f64` and made
//! camera-relative before the cast to `f32`, so worlds at 1e5..1e7 keep
//! sub-pixel precision (DESIGN §3).

use bytemuck::{Pod, Zeroable};
use glam::{DMat3, DMat4, DVec3, DVec4, Mat4};

use crate::{LightKind, LightState, Material, Scene, Texture};
use protocol::Camera;

/// Most lights a frame shades with.
pub const MAX_LIGHTS: usize = 4;

/// One light as the shader reads it.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LightGpu {
    pos_kind: [f32; 4],
    dir_cos: [f32; 4],
    color_shadow: [f32; 4],
}

/// `FrameUniforms` in `common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct FrameGpu {
    view_from_camrel: [[f32; 4]; 4],
    clip_from_view: [[f32; 4]; 4],
    prev_clip_from_camrel: [[f32; 4]; 4],
    shadow_from_camrel: [[f32; 4]; 4],
    size: [f32; 4],
    ray: [f32; 4],
    tan_half: [f32; 4],
    ambient: [f32; 4],
    sky_zenith: [f32; 4],
    sky_horizon: [f32; 4],
    sky_flat: [f32; 4],
    sun: [f32; 4],
    sun_dir: [f32; 4],
    flags: [u32; 4],
    lights: [LightGpu; MAX_LIGHTS],
}

/// `ObjectUniforms` in `common.wgsl`, padded to the 256-byte dynamic offset
/// alignment.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ObjectGpu {
    model: [[f32; 4]; 4],
    prev_model: [[f32; 4]; 4],
    normal_m: [[f32; 4]; 4],
    albedo: [f32; 4],
    emissive: [f32; 4],
    texture: [f32; 4],
    ids: [u32; 4],
}

/// Bytes between consecutive objects in the object uniform buffer.
pub const OBJECT_STRIDE: u64 = 256;
const _: () = assert!(std::mem::size_of::<ObjectGpu>() as u64 == OBJECT_STRIDE);

fn f32_mat(m: DMat4) -> [[f32; 4]; 4] {
    m.as_mat4().to_cols_array_2d()
}

/// Maps standard [0, 1] clip depth to reversed Z (near → 1, far → 0), which
/// spreads depth-buffer precision evenly; linear depth is output separately.
fn reverse_z() -> DMat4 {
    DMat4::from_cols(
        DVec4::new(1.0, 0.0, 0.0, 0.0),
        DVec4::new(0.0, 1.0, 0.0, 0.0),
        DVec4::new(0.0, 0.0, -1.0, 0.0),
        DVec4::new(0.0, 0.0, 1.0, 1.0),
    )
}

/// The rotation-only world → view matrix (camera-relative input).
pub fn view_from_camrel(camera: &Camera) -> DMat4 {
    DMat4::from_quat(camera.pose.rotation.normalize().conjugate())
}

/// Translation from camera-relative to world coordinates.
pub fn world_from_camrel(camera: &Camera) -> DMat4 {
    DMat4::from_translation(camera.pose.position)
}

/// Everything the frame uniforms need besides the scene.
pub struct FrameInputs<'a> {
    /// This frame's camera.
    pub camera: &'a Camera,
    /// The previous frame's camera (equal to `camera` on the first frame and
    /// after a cut).
    pub prev_camera: &'a Camera,
    /// Rendered size (w, h).
    pub size: (u32, u32),
    /// Previous rendered size (w, h).
    pub prev_size: (u32, u32),
    /// Lights at this instant.
    pub lights: &'a [LightState],
    /// Shadow map light clip from world, if the shadow pass runs.
    pub shadow_from_world: Option<DMat4>,
}

/// Builds the frame uniforms.
pub fn frame_uniforms(scene: &Scene, f: &FrameInputs) -> FrameGpu {
    use crate::Effect;
    let cam = f.camera;
    let camrel_to_world = world_from_camrel(cam);
    let clip_from_view = reverse_z() * cam.clip_from_view();
    let prev_clip_from_camrel =
        f.prev_camera.clip_from_view() * f.prev_camera.pose.world_to_view() * camrel_to_world;
    let shadow = f
        .shadow_from_world
        .map_or(DMat4::IDENTITY, |m| m * camrel_to_world);
    let w = &cam.window;
    let t = cam.projection.tan_half_fov();
    let mut lights = [LightGpu::default(); MAX_LIGHTS];
    let mut shadow_owner = f.shadow_from_world.is_some();
    for (gpu, l) in lights.iter_mut().zip(f.lights) {
        let (kind, cos) = match l.light.kind {
            LightKind::Directional { .. } => (0.0, 0.0),
            LightKind::Point { .. } => (1.0, 0.0),
            LightKind::Spot { angle_deg, .. } => (2.0, angle_deg.to_radians().cos() as f32),
        };
        let owns = shadow_owner && crate::casts_shadow(&l.light);
        if owns {
            shadow_owner = false;
        }
        let p = (l.position - cam.pose.position).as_vec3();
        let d = l.direction.as_vec3();
        let c = l.light.color.map(|v| v * l.light.intensity);
        *gpu = LightGpu {
            pos_kind: [p.x, p.y, p.z, kind],
            dir_cos: [d.x, d.y, d.z, cos],
            color_shadow: [c[0], c[1], c[2], if owns { 1.0 } else { 0.0 }],
        };
    }
    let sun_dir = f
        .lights
        .iter()
        .find(|l| matches!(l.light.kind, LightKind::Directional { .. }))
        .map_or(DVec3::Y, |l| -l.direction);
    let sky = &scene.sky;
    let v4 = |c: [f32; 3]| [c[0], c[1], c[2], 0.0];
    FrameGpu {
        view_from_camrel: f32_mat(view_from_camrel(cam)),
        clip_from_view: f32_mat(clip_from_view),
        prev_clip_from_camrel: f32_mat(prev_clip_from_camrel),
        shadow_from_camrel: f32_mat(shadow),
        size: [
            f.size.0 as f32,
            f.size.1 as f32,
            f.prev_size.0 as f32,
            f.prev_size.1 as f32,
        ],
        ray: [
            w.u0 as f32,
            w.v1 as f32,
            (w.width() / f64::from(f.size.0)) as f32,
            (w.height() / f64::from(f.size.1)) as f32,
        ],
        tan_half: [
            (t * cam.projection.aspect) as f32,
            t as f32,
            0.0,
            f32::INFINITY,
        ],
        ambient: v4(scene.ambient),
        sky_zenith: v4(sky.zenith),
        sky_horizon: v4(sky.horizon),
        sky_flat: v4(sky.flat),
        sun: [sky.sun[0], sky.sun[1], sky.sun[2], 0.9997],
        sun_dir: [sun_dir.x as f32, sun_dir.y as f32, sun_dir.z as f32, 0.0],
        flags: [
            u32::from(scene.has(Effect::Sky)),
            u32::from(scene.has(Effect::Specular)),
            u32::from(f.shadow_from_world.is_some()),
            f.lights.len().min(MAX_LIGHTS) as u32,
        ],
        lights,
    }
}

/// Builds one object's uniforms from its current and previous world matrix.
/// `instance` is written to the id target as `instance + 1`.
pub fn object_uniforms(
    camera: &Camera,
    instance: usize,
    model: DMat4,
    prev_model: DMat4,
    material: &Material,
) -> ObjectGpu {
    let to_camrel = DMat4::from_translation(-camera.pose.position);
    let normal = DMat3::from_mat4(model).inverse().transpose();
    let (kind, scale, contrast) = match material.texture {
        Texture::None => (0.0, 1.0, 0.0),
        Texture::Checker { scale, contrast } => (1.0, scale, contrast),
        Texture::Stripes { scale, contrast } => (2.0, scale, contrast),
        Texture::Noise { scale, contrast } => (3.0, scale, contrast),
        Texture::Grid { scale, line } => (4.0, scale, line),
    };
    let a = material.albedo;
    let e = material.emissive;
    ObjectGpu {
        model: f32_mat(to_camrel * model),
        prev_model: f32_mat(to_camrel * prev_model),
        normal_m: Mat4::from_mat3(normal.as_mat3()).to_cols_array_2d(),
        albedo: [a[0], a[1], a[2], material.alpha],
        emissive: [e[0], e[1], e[2], material.roughness],
        texture: [kind, scale, contrast, material.specular],
        ids: [instance as u32 + 1, 0, 0, 0],
    }
}

/// Shadow-map projection (standard Z, [0, 1]) for the light, fitted to a
/// world-space bounding sphere of the scene.
pub fn shadow_from_world(light: &LightState, center: DVec3, radius: f64) -> DMat4 {
    let radius = radius.max(1e-3);
    match light.light.kind {
        LightKind::Spot { angle_deg, .. } => {
            let eye = light.position;
            let view = DMat4::look_at_rh(eye, eye + light.direction, pick_up(light.direction));
            let far = (center - eye).length() + radius;
            let fov = (2.0 * angle_deg + 10.0)
                .to_radians()
                .min(170f64.to_radians());
            DMat4::perspective_rh(fov, 1.0, 0.05, far.max(0.1)) * view
        }
        _ => {
            let eye = center - light.direction * (2.0 * radius);
            let view = DMat4::look_at_rh(eye, center, pick_up(light.direction));
            DMat4::orthographic_rh(-radius, radius, -radius, radius, 0.0, 4.0 * radius) * view
        }
    }
}

fn pick_up(dir: DVec3) -> DVec3 {
    if dir.normalize().y.abs() > 0.99 {
        DVec3::Z
    } else {
        DVec3::Y
    }
}
