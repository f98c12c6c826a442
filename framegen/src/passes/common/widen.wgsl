// Widen the uploaded f16 colour to f32. See `widen.rs`.

struct WidenParams {
    sizes: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> wp: WidenParams;
@group(0) @binding(1) var<storage, read> narrow: array<vec2<u32>>;
@group(0) @binding(2) var<storage, read_write> color: array<vec4<f32>>;

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

@compute @workgroup_size(256)
fn widen(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    if t >= wp.sizes.x {
        return;
    }
    let h = narrow[t];
    color[t] = vec4<f32>(
        half_to_f32(h.x & 0xffffu),
        half_to_f32(h.x >> 16u),
        half_to_f32(h.y & 0xffffu),
        half_to_f32(h.y >> 16u),
    );
}
