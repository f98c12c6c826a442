// GFFE §4.2 layered background collection. See `background.rs`.

struct BgParams {
    camera: Cam,
    shift: vec4<f32>,
    config: vec4<u32>,
    level: vec4<u32>,
    next: vec4<u32>,
    prev: vec4<u32>,
};

@group(0) @binding(0) var<storage, read> bp: BgParams;
@group(0) @binding(1) var<storage, read> positions: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> track: array<u32>;
// The rendered frame's colour as uploaded: four f16 a pixel.
@group(0) @binding(3) var<storage, read> color: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> prev_bg: array<BgTexel>;
@group(0) @binding(5) var<storage, read_write> bg: array<BgTexel>;
@group(0) @binding(6) var<storage, read> keys: array<u32>;
@group(0) @binding(7) var<storage, read> winners: array<u32>;
@group(0) @binding(8) var<storage, read_write> candidates: array<vec2<u32>>;
// The history's `SeenAgain` flags of the previous frame's pixels (level 0).
@group(0) @binding(9) var<storage, read> seen_again: array<u32>;

@compute @workgroup_size(256)
fn bg_init(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let x = thread_index(wid, nwg, lid);
    if x >= bp.config.x {
        return;
    }
    let p = positions[x];
    if (track[x] & 3u) == 2u && p.w != W_INVALID {
        // Its f16 bits as they are, alpha 1 (0x3c00).
        let c = color[x];
        bg[x] = bg_texel(p, vec2<u32>(c.x, (c.y & 0xffffu) | (0x3c00u << 16u)));
    }
}

fn rebased(p: vec4<f32>) -> vec4<f32> {
    if p.w > 0.5 {
        return vec4<f32>(p.xyz + bp.shift.xyz, p.w);
    }
    return p;
}

@compute @workgroup_size(256)
fn bg_project(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = thread_index(wid, nwg, lid);
    if i >= bp.prev.y {
        return;
    }
    var out = vec2<u32>(NONE, 0u);
    let t = prev_bg[bp.prev.x + i];
    let l = bp.config.y;
    // A previous seed the current frame saw again (and no pixel of it
    // that is not confirmed landed in) is not reprojected.
    let again = l == 0u && seen_again[i] == 1u;
    if bg_valid(t) && !again {
        let r = project(bp.camera, rebased(bg_pos(t)));
        if r.ok {
            let s = cell(r.pixel, bp.level.y, bp.level.z, f32(1u << l));
            if s != NONE {
                let here = bg[bp.level.x + s];
                if !bg_valid(here) {
                    out = vec2<u32>(bp.level.x + s, depth_key(r.depth));
                } else if bp.next.w == 1u && r.depth > depth_of(bp.camera, bg_pos(here)) * (1.0 + bp.shift.w) {
                    let s1 = cell(r.pixel, bp.next.y, bp.next.z, f32(1u << (l + 1u)));
                    if s1 != NONE {
                        out = vec2<u32>(bp.next.x + s1, depth_key(r.depth));
                    }
                }
            }
        }
    }
    candidates[i] = out;
}

@compute @workgroup_size(256)
fn bg_resolve(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let s = bp.level.x + thread_index(wid, nwg, lid);
    if s >= bp.level.w {
        return;
    }
    let stored = winners[s];
    if stored == 0u {
        return;
    }
    let t = prev_bg[bp.prev.x + ~stored];
    bg[s] = bg_texel(rebased(bg_pos(t)), t.color);
}
