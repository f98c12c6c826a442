// Shared declarations and shading for the renderer's passes (prepended to
// each pass's shader). Positions are camera-relative: world axes, origin at
// the current camera, so huge worlds keep f32 precision (DESIGN §3).

const PI: f32 = 3.14159265;

struct Light {
    // xyz: camera-relative position; w: kind (0 directional, 1 point, 2 spot)
    pos_kind: vec4<f32>,
    // xyz: unit direction the light travels; w: cos of the spot half-angle
    dir_cos: vec4<f32>,
    // rgb: color × intensity; w: 1 if this light owns the shadow map
    color_shadow: vec4<f32>,
};

struct FrameUniforms {
    view_from_camrel: mat4x4<f32>,
    // Reversed-Z projection of the rendered window (near → 1, far → 0).
    clip_from_view: mat4x4<f32>,
    // Previous camera's projection × view, relative to the current camera
    // position: maps this frame's camera-relative points to last frame's clip.
    prev_clip_from_camrel: mat4x4<f32>,
    shadow_from_camrel: mat4x4<f32>,
    // width, height, previous width, previous height
    size: vec4<f32>,
    // u0, v1, (u1 - u0) / width, (v1 - v0) / height of the window
    ray: vec4<f32>,
    // tan(fov/2)·aspect, tan(fov/2), unused, +inf
    tan_half: vec4<f32>,
    ambient: vec4<f32>,
    sky_zenith: vec4<f32>,
    sky_horizon: vec4<f32>,
    sky_flat: vec4<f32>,
    // rgb: sun disc radiance; w: cos of the disc's angular radius
    sun: vec4<f32>,
    // xyz: unit direction towards the sun
    sun_dir: vec4<f32>,
    // x: sky effect, y: specular effect, z: shadows effect, w: light count
    flags: vec4<u32>,
    lights: array<Light, 4>,
};

struct ObjectUniforms {
    model: mat4x4<f32>,
    prev_model: mat4x4<f32>,
    normal_m: mat4x4<f32>,
    // rgb albedo, alpha
    albedo: vec4<f32>,
    // rgb emissive, roughness
    emissive: vec4<f32>,
    // texture kind, scale, contrast (or line width), specular strength
    texture: vec4<f32>,
    // x: instance id + 1 (0 is the background)
    ids: vec4<u32>,
};

@group(0) @binding(0) var<uniform> frame: FrameUniforms;
@group(1) @binding(0) var<uniform> object: ObjectUniforms;

// What the opaque, background and translucent passes write: HDR color,
// linear view depth, motion current → previous, instance id + 1. Depth and
// motion are f32 values stored as their bit patterns in integer targets
// (`targets.rs`): every backend renders R32Uint / Rg32Uint, while OpenGL
// cannot render R32Float. The readback is bit-identical either way.
struct GBufferOut {
    @location(0) color: vec4<f32>,
    @location(1) depth: u32,
    @location(2) motion: vec2<u32>,
    @location(3) id: u32,
};

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
};

// Continuous pixel position in the previous frame of a previous-frame clip
// position. A point behind the previous camera (w ≤ 0) is pushed far outside
// the image instead of producing NaN.
fn prev_pixel(prev_clip: vec4<f32>) -> vec2<f32> {
    let w = max(prev_clip.w, 1e-6);
    let ndc = prev_clip.xy / w;
    return vec2<f32>((ndc.x + 1.0) * 0.5 * frame.size.z, (1.0 - ndc.y) * 0.5 * frame.size.w);
}
