// GFFE Algorithm 1: history tracking with the static test. See `history.rs`.

struct HistoryParams {
    cur: Cam,
    prev: Cam,
    sizes: vec4<u32>,
    config: vec4<u32>,
    epsilon: vec4<f32>,
};

@group(0) @binding(0) var<storage, read> hp: HistoryParams;
@group(0) @binding(1) var<storage, read> depth: array<f32>;
@group(0) @binding(2) var<storage, read> motion: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read> prev_positions: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> prev_track: array<u32>;
@group(0) @binding(5) var<storage, read_write> positions: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> track: array<u32>;
@group(0) @binding(7) var<storage, read_write> dynamic_count: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read> prev_depth: array<f32>;
// `SeenAgain` of the previous pixels, `seen | unsure << 1` (cleared first).
@group(0) @binding(9) var<storage, read_write> seen_again: array<atomic<u32>>;

@compute @workgroup_size(256)
fn history(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let x = thread_index(wid, nwg, lid);
    let w = hp.sizes.x;
    let n = w * hp.sizes.y;
    if x >= n {
        return;
    }
    let k = hp.config.x;
    let d = depth[x];
    if !(d > 0.0) {
        for (var i = 0u; i < k; i++) {
            positions[i * n + x] = vec4<f32>(0.0, 0.0, 0.0, W_INVALID);
        }
        track[x] = 0u;
        return;
    }
    let center = vec2<f32>(f32(x % w) + 0.5, f32(x / w) + 0.5);
    let p = unproject(hp.cur, center, d);
    var word = (k - 1u) << 2u;
    var len = k - 1u;
    var is_static = true;
    var last = p;
    positions[x] = p;
    if hp.config.y == 1u {
        let target_px = center + motion[x];
        let r = project(hp.prev, p);
        let e = r.pixel - target_px;
        let eps = hp.epsilon.x;
        is_static = r.ok && e.x * e.x + e.y * e.y <= eps * eps;
        let j = cell(target_px, hp.sizes.z, hp.sizes.w, 1.0);
        // Confirmed where the point lands in the previous frame; a
        // negative tolerance: no background, nothing to confirm.
        let seen = cell(r.pixel, hp.sizes.z, hp.sizes.w, 1.0);
        var confirmed = false;
        if is_static && seen != NONE && hp.epsilon.y >= 0.0 {
            // The pixel's point, seen from the previous camera (`r`), is as
            // deep as the previous frame's depth there (`agrees`).
            let before = prev_depth[seen];
            var agrees = false;
            if p.w == W_DIRECTION {
                agrees = is_inf(before);
            } else {
                agrees = !is_inf(before) && abs(r.depth - before) <= hp.epsilon.y * before;
            }
            if agrees {
                word = word | 2u;
                confirmed = true;
            }
        }
        // The previous pixel it lands in (`flag`): seen where it was a
        // seed and this pixel is confirmed, unsure where it is not.
        if r.ok && seen != NONE && hp.epsilon.y >= 0.0 {
            if !confirmed {
                atomicOr(&seen_again[seen], 2u);
            } else if (prev_track[seen] & 3u) == 2u {
                atomicOr(&seen_again[seen], 1u);
            }
        }
        if !is_static {
            atomicAdd(&dynamic_count[0], 1u);
            len = 0u;
            let pn = hp.sizes.z * hp.sizes.w;
            if j != NONE {
                let prev_word = prev_track[j];
                var available = k - 1u;
                if (prev_word & 1u) == 1u {
                    available = (prev_word >> 2u) + 1u;
                }
                let limit = min(available, k - 1u);
                for (var i = 1u; i <= limit; i++) {
                    var q = prev_positions[(i - 1u) * pn + j];
                    if q.w > 0.5 {
                        q = vec4<f32>(q.xyz + hp.prev.eye.xyz, q.w);
                    }
                    if q.w != p.w {
                        break;
                    }
                    positions[i * n + x] = q;
                    last = q;
                    len = i;
                }
            }
            word = 1u | (len << 2u);
        }
    }
    if is_static {
        // Static: every entry is p.
        for (var i = 1u; i < k; i++) {
            positions[i * n + x] = p;
        }
    } else {
        for (var i = len + 1u; i < k; i++) {
            positions[i * n + x] = last;
        }
    }
    track[x] = word;
}
