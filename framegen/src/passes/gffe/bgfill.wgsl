// Background projection into the holes of a generated frame. See `bgfill.rs`.

struct FillParams {
    view: Cam,
    current: Cam,
    map: vec4<f32>,
    config: vec4<u32>,
    source_offsets: vec4<u32>,
    target_offsets: vec4<u32>,
    target_widths: vec4<u32>,
    target_heights: vec4<u32>,
    // Pixels of the rendered frame whose level-0 fragments may be skipped
    // (0: none), see `seeded`.
    seed: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> fp: FillParams;
@group(0) @binding(1) var<storage, read> bg: array<BgTexel>;
@group(0) @binding(2) var<storage, read> keys: array<u32>;
@group(0) @binding(3) var<storage, read> winners: array<u32>;
@group(0) @binding(4) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(6) var<storage, read_write> out_motion: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> out_mask: array<u32>;
@group(0) @binding(8) var<storage, read_write> candidates: array<vec2<u32>>;
@group(0) @binding(9) var<storage, read> track: array<u32>;
@group(0) @binding(10) var<storage, read> p0: array<vec4<f32>>;

// Whether texel `i` is a level-0 fragment this frame's own static pixel
// seeded (`background::seeds`): it lands where the warp already wrote and
// cannot fill a hole.
fn seeded(i: u32) -> bool {
    if i >= fp.seed.x {
        return false;
    }
    let w = track[i];
    return (w & 1u) == 0u && (w & 2u) == 2u && p0[i].w != W_INVALID;
}

@compute @workgroup_size(256)
fn bgfill_project(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i >= fp.config.y {
        return;
    }
    var out = vec2<u32>(NONE, 0u);
    if seeded(i) {
        candidates[i] = out;
        return;
    }
    let t = bg[i];
    if bg_valid(t) {
        var l = 0u;
        for (var j = 1u; j < fp.config.x; j++) {
            if i >= fp.source_offsets[j] {
                l = j;
            }
        }
        let r = project(fp.view, bg_pos(t));
        if r.ok {
            let s = cell(r.pixel, fp.target_widths[l], fp.target_heights[l], f32(1u << l));
            if s != NONE {
                out = vec2<u32>(fp.target_offsets[l] + s, depth_key(r.depth));
            }
        }
    }
    candidates[i] = out;
}

@compute @workgroup_size(256)
fn bgfill_resolve(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let w = fp.config.z;
    if t >= w * fp.config.w || out_mask[t] != EMPTY_MASK {
        return;
    }
    let center = vec2<f32>(f32(t % w) + 0.5, f32(t / w) + 0.5);
    var best_key = 0u;
    var best = NONE;
    for (var l = 0u; l < fp.config.x; l++) {
        let s = cell(center, fp.target_widths[l], fp.target_heights[l], f32(1u << l));
        if s == NONE {
            continue;
        }
        let slot = fp.target_offsets[l] + s;
        let stored = winners[slot];
        // Strictly nearer: ties stay with the finer level.
        if stored != 0u && keys[slot] > best_key {
            best_key = keys[slot];
            best = ~stored;
        }
    }
    if best == NONE {
        return;
    }
    let texel = bg[best];
    var motion = vec2<f32>(0.0);
    let r = project(fp.current, bg_pos(texel));
    if r.ok {
        motion = (r.pixel - fp.map.xy) * fp.map.zw - center;
    }
    out_color[t] = vec4<f32>(half4_to_f32(texel.color).xyz, 1.0);
    out_depth[t] = key_depth(best_key);
    out_motion[t] = motion;
    out_mask[t] = BACKGROUND_MASK;
}
