// Crop (and resample) the displayed region of a widened window. See `crop.rs`.

struct CropParams {
    sizes: vec4<u32>,
    rect: vec4<f32>,
};

@group(0) @binding(0) var<storage, read> cp: CropParams;
@group(0) @binding(1) var<storage, read> color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> depth: array<f32>;
@group(0) @binding(3) var<storage, read> motion: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> out_motion: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> out_mask: array<u32>;

fn clamp_index(p: vec2<f32>) -> u32 {
    let x = min(u32(max(p.x, 0.0)), cp.sizes.x - 1u);
    let y = min(u32(max(p.y, 0.0)), cp.sizes.y - 1u);
    return y * cp.sizes.x + x;
}

@compute @workgroup_size(256)
fn crop(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let ow = cp.sizes.z;
    if t >= ow * cp.sizes.w {
        return;
    }
    let out_size = vec2<f32>(f32(ow), f32(cp.sizes.w));
    let center = vec2<f32>(f32(t % ow) + 0.5, f32(t / ow) + 0.5);
    let s = cp.rect.xy + center * (cp.rect.zw / out_size);
    let q = s - 0.5;
    let base = floor(q);
    let f = q - base;
    let c00 = color[clamp_index(base)];
    let c10 = color[clamp_index(base + vec2<f32>(1.0, 0.0))];
    let c01 = color[clamp_index(base + vec2<f32>(0.0, 1.0))];
    let c11 = color[clamp_index(base + vec2<f32>(1.0, 1.0))];
    let rgb = (c00 * (1.0 - f.x) + c10 * f.x) * (1.0 - f.y) + (c01 * (1.0 - f.x) + c11 * f.x) * f.y;
    let nearest = clamp_index(s);
    out_color[t] = vec4<f32>(rgb.xyz, 1.0);
    out_depth[t] = depth[nearest];
    out_motion[t] = motion[nearest] * (out_size / cp.rect.zw);
    out_mask[t] = COPIED_MASK;
}
