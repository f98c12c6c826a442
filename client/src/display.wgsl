// The fixed display transform (DESIGN §3 "Color"; `protocol::display` is
// its CPU reference) as a full-screen draw: linear HDR RGB → exposure 1 →
// Reinhard → sRGB OETF → [0, 1]. The target is the size of the source, so
// each fragment reads its own texel.

@group(0) @binding(0) var linear_hdr: texture_2d<f32>;

@vertex
fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * vec2<f32>(2.0, -2.0) + vec2<f32>(-1.0, 1.0), 0.0, 1.0);
}

// Reinhard `x / (1 + x)`; NaN, negatives and −inf give 0, +inf gives 1.
// Tested on the bits: a shader compiler may assume floats are never NaN.
fn reinhard(x: f32) -> f32 {
    let bits = bitcast<u32>(x);
    if (bits == 0x7f800000u) {
        return 1.0;
    }
    if ((bits & 0x7fffffffu) > 0x7f800000u || (bits >> 31u) != 0u || x <= 0.0) {
        return 0.0;
    }
    return x / (1.0 + x);
}

// The sRGB OETF (IEC 61966-2-1) of a value in [0, 1].
fn srgb_oetf(v: f32) -> f32 {
    if (v <= 0.0031308) {
        return 12.92 * v;
    }
    if (v >= 1.0) {
        return 1.0;
    }
    return 1.055 * pow(v, 1.0 / 2.4) - 0.055;
}

fn texel(at: vec4<f32>) -> vec3<f32> {
    let c = textureLoad(linear_hdr, vec2<i32>(at.xy), 0);
    return vec3<f32>(reinhard(c.r), reinhard(c.g), reinhard(c.b));
}

// Into a plain UNORM target: the whole transform.
@fragment
fn fs_encoded(@builtin(position) at: vec4<f32>) -> @location(0) vec4<f32> {
    let t = texel(at);
    let e = vec3<f32>(srgb_oetf(t.r), srgb_oetf(t.g), srgb_oetf(t.b));
    return vec4<f32>(clamp(e, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}

// Into an sRGB target, which applies the OETF as it stores: Reinhard only.
@fragment
fn fs_linear(@builtin(position) at: vec4<f32>) -> @location(0) vec4<f32> {
    return vec4<f32>(texel(at), 1.0);
}
