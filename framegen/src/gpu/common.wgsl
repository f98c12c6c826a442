// Shared by every framegen pass; mirrored in Rust by `camera.rs` and
// `splat.rs` (the CPU reference). Keep the two in step.

// A camera as the passes see it (see `camera.rs` `PassCamera`).
struct Cam {
    // Columns of the world-from-view rotation (w unused).
    col0: vec4<f32>,
    col1: vec4<f32>,
    col2: vec4<f32>,
    // Camera centre relative to the pass's reference origin (w unused).
    eye: vec4<f32>,
    // tan(fov_y / 2) * aspect, tan(fov_y / 2), pixel scales a_x, a_y.
    proj: vec4<f32>,
    // The ray map: pixel p looks along (r.x + p.x * r.y, r.z + p.y * r.w, -1)
    // in view space (window, image size and proj folded in).
    ray: vec4<f32>,
    // Image width, height (pixels), pixel offsets b_x, b_y: a view-space
    // point v at depth z lands at (v.x / z * a_x + b_x, v.y / z * a_y + b_y).
    size: vec4<f32>,
};

// A projected point: continuous pixel position and depth key; `ok` is false
// for points behind the camera or non-finite positions.
struct Proj {
    pixel: vec2<f32>,
    depth: f32,
    ok: bool,
};

const W_POINT: f32 = 1.0;
const W_DIRECTION: f32 = 0.0;
const W_INVALID: f32 = -1.0;
const INF_BITS: u32 = 0x7f800000u;
const NONE: u32 = 0xffffffffu;

fn thread_index(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * 256u + lid;
}

fn inf_f32() -> f32 {
    return bitcast<f32>(INF_BITS);
}

fn is_inf(d: f32) -> bool {
    return bitcast<u32>(d) == INF_BITS;
}

// Position (w = 1) or direction (w = 0) seen through pixel centre `px` at
// linear depth `d` (> 0, +inf for sky). Relative to the reference origin.
fn unproject(cam: Cam, px: vec2<f32>, d: f32) -> vec4<f32> {
    let ray = vec3<f32>(cam.ray.x + px.x * cam.ray.y, cam.ray.z + px.y * cam.ray.w, -1.0);
    let world = cam.col0.xyz * ray.x + cam.col1.xyz * ray.y + cam.col2.xyz * ray.z;
    if is_inf(d) {
        return vec4<f32>(normalize(world), W_DIRECTION);
    }
    return vec4<f32>(cam.eye.xyz + world * d, W_POINT);
}

fn project(cam: Cam, p: vec4<f32>) -> Proj {
    var out: Proj;
    out.ok = false;
    out.pixel = vec2<f32>(0.0);
    out.depth = 0.0;
    if p.w < 0.0 {
        return out;
    }
    var rel = p.xyz;
    if p.w > 0.5 {
        rel = p.xyz - cam.eye.xyz;
    }
    let v = vec3<f32>(dot(cam.col0.xyz, rel), dot(cam.col1.xyz, rel), dot(cam.col2.xyz, rel));
    let z = -v.z;
    if !(z > 0.0) {
        return out;
    }
    let inv = 1.0 / z;
    let px = v.x * inv * cam.proj.z + cam.size.z;
    let py = v.y * inv * cam.proj.w + cam.size.w;
    // Far off-screen values are rejected by the bounds tests of the callers;
    // keep them finite-comparable.
    out.pixel = vec2<f32>(px, py);
    if p.w > 0.5 {
        out.depth = z;
    } else {
        out.depth = inf_f32();
    }
    out.ok = abs(px) < 1e30 && abs(py) < 1e30;
    return out;
}

// Linear view depth of a stored position (`camera.rs` `depth_of`): +inf for
// a direction (the caller rejects invalid slots).
fn depth_of(cam: Cam, p: vec4<f32>) -> f32 {
    if p.w < 0.5 {
        return inf_f32();
    }
    return -dot(cam.col2.xyz, p.xyz - cam.eye.xyz);
}

// Linear index of the pixel containing continuous position `px` in a
// `w` x `h` grid scaled down by `scale`, or NONE outside.
fn cell(px: vec2<f32>, w: u32, h: u32, scale: f32) -> u32 {
    let q = px / scale;
    if !(q.x >= 0.0 && q.y >= 0.0 && q.x < f32(w) && q.y < f32(h)) {
        return NONE;
    }
    return u32(q.y) * w + u32(q.x);
}

// Splat key of a depth: larger is nearer, 0 is "empty" (see `splat.rs`).
fn depth_key(d: f32) -> u32 {
    return ~bitcast<u32>(d);
}

fn key_depth(k: u32) -> f32 {
    return bitcast<f32>(~k);
}

// Generated-pixel sources (see `output.rs`).
const EMPTY_MASK: u32 = 0u;
const WARPED_MASK: u32 = 1u;
const BACKGROUND_MASK: u32 = 2u;
const FILLED_MASK: u32 = 3u;
const COPIED_MASK: u32 = 4u;
const CRACK_MASK: u32 = 5u;

// The f16 in the low 16 bits of `h` as an f32, exactly: normal values by
// moving the bits, subnormals as a multiple of 2^-24 (an exact product),
// ±inf and NaN kept (sanitised colour has none). Without branches: the
// lanes of a software rasteriser's SIMD loop stay together.
fn half_to_f32(h: u32) -> f32 {
    let sign = (h & 0x8000u) << 16u;
    let e = (h >> 10u) & 0x1fu;
    let m = h & 0x3ffu;
    let subnormal = bitcast<u32>(ldexp(f32(m), -24));
    let normal = select((e + 112u) << 23u, 0x7f800000u, e == 31u) | (m << 13u);
    return bitcast<f32>(sign | select(normal, subnormal, e == 0u));
}

// Four f16 packed as two words (an `[f16; 4]`, little-endian) as f32,
// exactly (`half_to_f32`).
fn half4_to_f32(h: vec2<u32>) -> vec4<f32> {
    return vec4<f32>(
        half_to_f32(h.x & 0xffffu),
        half_to_f32(h.x >> 16u),
        half_to_f32(h.y & 0xffffu),
        half_to_f32(h.y >> 16u),
    );
}

// A background fragment (`background.rs` `Texel`, 24 bytes), read by
// background collection and background fill: its position, then its
// colour as the rendered frame's four f16 (alpha 1 = valid, 0 = empty, so a
// cleared buffer is empty).
struct BgTexel {
    pos_xy: vec2<f32>,
    pos_zw: vec2<f32>,
    color: vec2<u32>,
};

fn bg_texel(p: vec4<f32>, color: vec2<u32>) -> BgTexel {
    return BgTexel(p.xy, p.zw, color);
}

fn bg_pos(t: BgTexel) -> vec4<f32> {
    return vec4<f32>(t.pos_xy, t.pos_zw);
}

// Whether the slot holds a fragment: its alpha (the high half of the
// second word) is not 0.
fn bg_valid(t: BgTexel) -> bool {
    return (t.color.y >> 16u) != 0u;
}
