// Forward warp: project next positions, then resolve the splat winners.
// See `warp.rs`. Bindings are shared by both entry points.

// Mirrors `warp.rs` CRACK_DEPTH_RATIO (one surface).
const CRACK_DEPTH_RATIO: f32 = SAME_SURFACE_RATIO;

struct WarpParams {
    view: Cam,
    sizes: vec4<u32>,
    map: vec4<f32>,
    // x: the colour filter (`resample.rs` `Resample::code`), y: source
    // height.
    resample: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> wp: WarpParams;
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
// resolve only: the positions at α (where winners land) and the source
// frame's depth (which taps share the winner's surface).
@group(0) @binding(9) var<storage, read> landing_next: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read> source_depth: array<f32>;

// `resample.wgsl`'s source: the rendered frame.
fn rs_color(k: u32) -> vec4<f32> {
    return source[k];
}

fn rs_depth(k: u32) -> f32 {
    return source_depth[k];
}

fn rs_size() -> vec2<i32> {
    return vec2<i32>(i32(wp.sizes.w), i32(wp.resample.y));
}

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
    // `resample.rs` `position`: where the centre maps back to.
    let mode = wp.resample.x;
    var at = src;
    if mode != RESAMPLE_NEAREST {
        let landing = project(wp.view, landing_next[i]).pixel;
        let per_pixel = vec2<f32>(1.0) / wp.map.zw;
        at = src + clamp((center - landing) * per_pixel, vec2<f32>(-0.5), vec2<f32>(0.5));
    }
    let c = resample_at(i, at, mode);
    let disp = (at - wp.map.xy) * wp.map.zw;
    out_color[t] = vec4<f32>(c, 1.0);
    out_depth[t] = key_depth(keys[t]);
    out_motion[t] = disp - center;
    out_mask[t] = WARPED_MASK;
}

@compute @workgroup_size(256)
fn warp_cracks(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let w = i32(wp.sizes.y);
    let h = i32(wp.sizes.z);
    if t >= wp.sizes.y * wp.sizes.z || out_mask[t] != EMPTY_MASK {
        return;
    }
    let x = i32(t) % w;
    let y = i32(t) / w;
    // Pairs of opposite neighbours, in the order of `warp.rs` PAIRS.
    var pairs = array<vec4<i32>, 4>(
        vec4<i32>(-1, 0, 1, 0),
        vec4<i32>(0, -1, 0, 1),
        vec4<i32>(-1, -1, 1, 1),
        vec4<i32>(1, -1, -1, 1),
    );
    for (var p = 0; p < 4; p++) {
        let q = pairs[p];
        let ax = x + q.x;
        let ay = y + q.y;
        let bx = x + q.z;
        let by = y + q.w;
        if ax < 0 || ay < 0 || ax >= w || ay >= h || bx < 0 || by < 0 || bx >= w || by >= h {
            continue;
        }
        let a = u32(ay * w + ax);
        let b = u32(by * w + bx);
        if out_mask[a] != WARPED_MASK || out_mask[b] != WARPED_MASK {
            continue;
        }
        let da = out_depth[a];
        let db = out_depth[b];
        if max(da, db) > min(da, db) * CRACK_DEPTH_RATIO {
            continue;
        }
        let ca = out_color[a];
        let cb = out_color[b];
        out_color[t] = vec4<f32>((ca.xyz + cb.xyz) * 0.5, 1.0);
        out_depth[t] = (da + db) * 0.5;
        out_motion[t] = (out_motion[a] + out_motion[b]) * 0.5;
        out_mask[t] = CRACK_MASK;
        return;
    }
}
