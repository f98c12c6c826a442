// GeoMotionGen passes 2-4: normalize, reproject, merge. See `reproject.rs`.

struct InterpParams {
    size: vec4<u32>,
    alpha: vec4<f32>,
};

@group(0) @binding(0) var<storage, read> ip: InterpParams;
@group(0) @binding(1) var<storage, read> motion: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read> depth: array<f32>;
@group(0) @binding(3) var<storage, read> winners: array<u32>;
@group(0) @binding(4) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> out_motion: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> out_mask: array<u32>;
// normalize: written; project / merge: read.
@group(0) @binding(8) var<storage, read_write> uv: array<vec2<f32>>;
@group(0) @binding(9) var<storage, read_write> candidates: array<vec2<u32>>;

@compute @workgroup_size(256)
fn interp_normalize(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i >= ip.size.x * ip.size.y {
        return;
    }
    uv[i] = motion[i] / vec2<f32>(f32(ip.size.x), f32(ip.size.y));
}

@compute @workgroup_size(256)
fn interp_project(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    let w = ip.size.x;
    if i >= w * ip.size.y {
        return;
    }
    var out = vec2<u32>(NONE, 0u);
    let d = depth[i];
    if d > 0.0 {
        let size = vec2<f32>(f32(w), f32(ip.size.y));
        let center = vec2<f32>(f32(i % w) + 0.5, f32(i / w) + 0.5);
        let at = center + uv[i] * size * (1.0 - ip.alpha.x);
        let slot = cell(at, w, ip.size.y, 1.0);
        if slot != NONE {
            out = vec2<u32>(slot, depth_key(d));
        }
    }
    candidates[i] = out;
}

@compute @workgroup_size(256)
fn interp_merge(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    if t >= ip.size.x * ip.size.y {
        return;
    }
    let stored = winners[t];
    if stored == 0u {
        out_mask[t] = EMPTY_MASK;
        return;
    }
    let i = ~stored;
    out_motion[t] = uv[i];
    out_depth[t] = depth[i];
    out_color[t] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    out_mask[t] = WARPED_MASK;
}
