// Forward warp: project next positions, then resolve the splat winners.
// See `warp.rs`. Bindings are shared by both entry points.

struct WarpParams {
    view: Cam,
    sizes: vec4<u32>,
    map: vec4<f32>,
};

@group(0) @binding(0) var<uniform> wp: WarpParams;
// project: next positions; resolve: source color.
@group(0) @binding(1) var<storage, read> source: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> keys: array<u32>;
@group(0) @binding(3) var<storage, read> winners: array<u32>;
@group(0) @binding(4) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> out_motion: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> out_mask: array<u32>;
// project only.
@group(0) @binding(8) var<storage, read_write> candidates: array<vec2<u32>>;

@compute @workgroup_size(256)
fn warp_project(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i >= wp.sizes.x {
        return;
    }
    let r = project(wp.view, source[i]);
    var slot = NONE;
    var key = 0u;
    if r.ok {
        slot = cell(r.pixel, wp.sizes.y, wp.sizes.z, 1.0);
        if slot != NONE {
            key = depth_key(r.depth);
        }
    }
    candidates[i] = vec2<u32>(slot, key);
}

@compute @workgroup_size(256)
fn warp_resolve(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let w = wp.sizes.y;
    if t >= w * wp.sizes.z {
        return;
    }
    let stored = winners[t];
    if stored == 0u {
        return;
    }
    let i = ~stored;
    let sw = wp.sizes.w;
    let center = vec2<f32>(f32(t % w) + 0.5, f32(t / w) + 0.5);
    let src = vec2<f32>(f32(i % sw) + 0.5, f32(i / sw) + 0.5);
    let disp = (src - wp.map.xy) * wp.map.zw;
    let c = source[i];
    out_color[t] = vec4<f32>(c.xyz, 1.0);
    out_depth[t] = key_depth(keys[t]);
    out_motion[t] = disp - center;
    out_mask[t] = WARPED_MASK;
}
