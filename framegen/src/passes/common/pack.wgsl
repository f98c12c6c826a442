// Pack the generated frame for the host: f16 colour, sanitised depth and
// motion (in place), a byte per pixel for its source. See `pack.rs`.

struct PackParams {
    sizes: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> kp: PackParams;
@group(0) @binding(1) var<storage, read> color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> depth: array<u32>;
@group(0) @binding(3) var<storage, read_write> motion: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> mask: array<u32>;
@group(0) @binding(5) var<storage, read_write> out_color: array<vec2<u32>>;
@group(0) @binding(6) var<storage, read_write> out_mask: array<u32>;

// The exponent bits of an f32: all set for ±inf and NaN.
const EXPONENT: u32 = 0x7f800000u;
// The bits of 65504, the largest f16.
const MAX_RADIANCE_BITS: u32 = 0x477fe000u;
// 1.0 as an f16.
const HALF_ONE: u32 = 0x3c00u;

// `x` shifted right by `s` (1..=24), rounded to nearest, ties to even.
fn shift_round(x: u32, s: u32) -> u32 {
    let q = x >> s;
    let r = x & ((1u << s) - 1u);
    let mid = 1u << (s - 1u);
    return q + select(0u, 1u, r > mid || (r == mid && (q & 1u) == 1u));
}

// A colour channel as f16 bits: non-finite and non-positive values to +0,
// the rest clamped to 65504 and rounded to nearest (ties to even), like the
// CPU's conversion. On bits: positive floats order like their bit patterns,
// and every negative one (sign bit set) compares above `EXPONENT`. Both
// roundings are computed and one is selected, without branches (the lanes
// of a software rasteriser's SIMD loop stay together).
fn radiance_half(v: f32) -> u32 {
    let x = bitcast<u32>(v);
    let y = min(x, MAX_RADIANCE_BITS);
    let e = i32(y >> 23u) - 127;
    let m = y & 0x7fffffu;
    // A subnormal f16 (e < -14): the value in units of 2^-24.
    let subnormal = shift_round(m | 0x800000u, u32(clamp(-e - 1, 14, 24)));
    // A normal one: a carry out of the mantissa moves the exponent up, as
    // it should.
    let normal = shift_round((u32(max(e + 15, 0)) << 23u) | m, 13u);
    let h = select(normal, subnormal, e < -14);
    // Below half the smallest subnormal, zero, negative or not finite.
    return select(h, 0u, e < -25 || x >= EXPONENT);
}

// The byte of `PixelSource` a pass's mask value reports (warped for a
// closed crack, filled for anything else unknown).
fn source(m: u32) -> u32 {
    return select(select(select(3u, 4u, m == 4u), 2u, m == 2u), 1u, m == 1u || m == 5u);
}

@compute @workgroup_size(256)
fn pack(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let n = kp.sizes.x;
    if t >= n {
        return;
    }
    let c = color[t];
    out_color[t] = vec2<u32>(
        radiance_half(c.x) | (radiance_half(c.y) << 16u),
        radiance_half(c.z) | (HALF_ONE << 16u),
    );
    // Depth: positive values (+inf, the sky, among them) are kept; NaN,
    // zero and negative ones become +inf (no surface).
    let d = depth[t];
    depth[t] = select(EXPONENT, d, d > 0u && d <= EXPONENT);
    let mv = motion[t];
    motion[t] = select(mv, vec2<u32>(0u), (mv & vec2<u32>(EXPONENT)) == vec2<u32>(EXPONENT));
    // The first pixel of each four writes their source word.
    if (t & 3u) == 0u {
        var bytes = 0u;
        for (var j = 0u; j < 4u && t + j < n; j++) {
            bytes |= source(mask[t + j]) << (8u * j);
        }
        out_mask[t / 4u] = bytes;
    }
}
