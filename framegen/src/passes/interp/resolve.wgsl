// GeoMotionGen pass 7: fuse the current and previous frames. See `resolve.rs`.

struct ResolveParams {
    size: vec4<u32>,
    alpha: vec4<f32>,
};

@group(0) @binding(0) var<uniform> rp: ResolveParams;
@group(0) @binding(1) var<storage, read> cur_color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> cur_depth: array<f32>;
@group(0) @binding(3) var<storage, read> prev_color: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> prev_depth: array<f32>;
@group(0) @binding(5) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(7) var<storage, read_write> out_motion: array<vec2<f32>>;
@group(0) @binding(8) var<storage, read_write> out_mask: array<u32>;

fn clamped(p: vec2<f32>) -> u32 {
    let x = min(u32(max(p.x, 0.0)), rp.size.x - 1u);
    let y = min(u32(max(p.y, 0.0)), rp.size.y - 1u);
    return y * rp.size.x + x;
}

fn fetch(current: bool, p: vec2<f32>) -> vec4<f32> {
    let q = p - 0.5;
    let base = floor(q);
    let f = q - base;
    let i00 = clamped(base);
    let i10 = clamped(base + vec2<f32>(1.0, 0.0));
    let i01 = clamped(base + vec2<f32>(0.0, 1.0));
    let i11 = clamped(base + vec2<f32>(1.0, 1.0));
    var c00: vec4<f32>;
    var c10: vec4<f32>;
    var c01: vec4<f32>;
    var c11: vec4<f32>;
    if current {
        c00 = cur_color[i00];
        c10 = cur_color[i10];
        c01 = cur_color[i01];
        c11 = cur_color[i11];
    } else {
        c00 = prev_color[i00];
        c10 = prev_color[i10];
        c01 = prev_color[i01];
        c11 = prev_color[i11];
    }
    return (c00 * (1.0 - f.x) + c10 * f.x) * (1.0 - f.y) + (c01 * (1.0 - f.x) + c11 * f.x) * f.y;
}

@compute @workgroup_size(256)
fn interp_resolve(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let w = rp.size.x;
    if t >= w * rp.size.y {
        return;
    }
    let alpha = rp.alpha.x;
    let center = vec2<f32>(f32(t % w) + 0.5, f32(t / w) + 0.5);
    let m = out_motion[t] * vec2<f32>(f32(w), f32(rp.size.y));
    let written = out_mask[t] == WARPED_MASK;
    var at = center + m * alpha;
    if written {
        at = center - m * (1.0 - alpha);
    }
    let c = fetch(written, at);
    out_color[t] = vec4<f32>(c.xyz, 1.0);
    if written {
        out_depth[t] = cur_depth[clamped(at)];
    } else {
        out_depth[t] = prev_depth[clamped(at)];
    }
    out_motion[t] = m * alpha;
}
