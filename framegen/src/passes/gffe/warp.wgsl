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

// Mirrors `resample.rs`.
const RESAMPLE_NEAREST: u32 = 0u;
const RESAMPLE_CATMULL_ROM: u32 = 2u;
const SAME_SURFACE_RATIO: f32 = 1.1;
const RESAMPLE_FLAT: f32 = 1.0 / 4096.0;

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
// resolve only: the positions at α (where winners land) and the source
// frame's depth (which taps share the winner's surface).
@group(0) @binding(9) var<storage, read> landing_next: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read> source_depth: array<f32>;

fn same_surface(a: f32, b: f32) -> bool {
    // Skies compared by their bits (no arithmetic on infinities here).
    if is_inf(a) || is_inf(b) {
        return bitcast<u32>(a) == bitcast<u32>(b);
    }
    if a >= b {
        return b > 0.0 && a <= b * SAME_SURFACE_RATIO;
    }
    return a > 0.0 && b <= a * SAME_SURFACE_RATIO;
}

fn catmull_rom(f: f32) -> vec4<f32> {
    let f2 = f * f;
    let f3 = f2 * f;
    return vec4<f32>(
        -0.5 * f3 + f2 - 0.5 * f,
        1.5 * f3 - 2.5 * f2 + 1.0,
        -1.5 * f3 + 2.0 * f2 + 0.5 * f,
        0.5 * f3 - 0.5 * f2,
    );
}

// Tap (dx, dy) from `base`, clamped into the source image.
fn tap_index(base: vec2<i32>, dx: i32, dy: i32) -> u32 {
    let sw = i32(wp.sizes.w);
    let sh = i32(wp.resample.y);
    let x = clamp(base.x + dx, 0, sw - 1);
    let y = clamp(base.y + dy, 0, sh - 1);
    return u32(y * sw + x);
}

// `resample.rs` `resample`: the source colour at `at` on pixel `own`'s
// surface.
fn resample_at(own: u32, at: vec2<f32>, mode: u32) -> vec3<f32> {
    let fallback = source[own].xyz;
    if mode == RESAMPLE_NEAREST {
        return fallback;
    }
    let d0 = source_depth[own];
    let q = at - 0.5;
    let basef = floor(q);
    let f = q - basef;
    let base = vec2<i32>(basef);
    // The inner 2×2 bounds every result; flat to the f16 output's rounding,
    // the pixel itself (`resample.rs` FLAT).
    let c0 = source[tap_index(base, 0, 0)];
    let c1 = source[tap_index(base, 1, 0)];
    let c2 = source[tap_index(base, 0, 1)];
    let c3 = source[tap_index(base, 1, 1)];
    let lo = min(min(c0, c1), min(c2, c3));
    let hi = max(max(c0, c1), max(c2, c3));
    if all((hi - lo) <= hi * RESAMPLE_FLAT) {
        return fallback;
    }
    if mode == RESAMPLE_CATMULL_ROM {
        var on_surface = true;
        for (var j = 0; j < 4; j++) {
            for (var i = 0; i < 4; i++) {
                on_surface = on_surface && same_surface(source_depth[tap_index(base, i - 1, j - 1)], d0);
            }
        }
        if on_surface {
            // Separable: each row along x, then the rows along y.
            let wx = catmull_rom(f.x);
            let wy = catmull_rom(f.y);
            var sum = vec4<f32>(0.0);
            for (var j = 0; j < 4; j++) {
                var across = vec4<f32>(0.0);
                for (var i = 0; i < 4; i++) {
                    across += source[tap_index(base, i - 1, j - 1)] * wx[i];
                }
                sum += across * wy[j];
            }
            return clamp(sum, lo, hi).xyz;
        }
    }
    var sum = vec4<f32>(0.0);
    var weight = 0.0;
    for (var t = 0; t < 4; t++) {
        let dx = t % 2;
        let dy = t / 2;
        let k = tap_index(base, dx, dy);
        if same_surface(source_depth[k], d0) {
            let fx = select(1.0 - f.x, f.x, dx == 1);
            let fy = select(1.0 - f.y, f.y, dy == 1);
            sum += source[k] * (fx * fy);
            weight += fx * fy;
        }
    }
    if weight > 1e-6 {
        return (sum / weight).xyz;
    }
    return fallback;
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
        at = src + clamp((center - landing) / wp.map.zw, vec2<f32>(-0.5), vec2<f32>(0.5));
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
