// Shading correction (GFFE §4.4), hand-built. See `shading.rs`, whose CPU
// reference these kernels mirror operation by operation.

struct ShadingParams {
    // width, height, blocks per row, blocks per column
    size: vec4<u32>,
    // whether frame t-1 has a ratio plane
    flags: vec4<u32>,
    // alpha
    alpha: vec4<f32>,
};

const LUMA_FLOOR: f32 = 1e-3;
const MAX_LOG_RATIO: f32 = 4.0;
const BLOCK: u32 = 8u;
const SEARCH: i32 = 8;
const MIN_ENERGY: f32 = 2.0;
const FOCUS_LOW: f32 = 0.01;
const FOCUS_HIGH: f32 = 0.05;
const MAX_STEPS: f32 = 4.0;
const QUANTUM: f32 = 1.0 / 256.0;
const COHERENCE: f32 = 0.5;

@group(0) @binding(0) var<uniform> sp: ShadingParams;
@group(0) @binding(1) var<storage, read> sh_color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> sh_depth: array<f32>;
@group(0) @binding(3) var<storage, read> sh_motion: array<vec2<f32>>;
@group(0) @binding(4) var<storage, read> sh_track: array<u32>;
@group(0) @binding(5) var<storage, read> sh_prev_color: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> sh_prev_ratio: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> sh_ratio: array<vec2<f32>>;
@group(0) @binding(8) var<storage, read_write> sh_flow: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> sh_out: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read> sh_prev_depth: array<f32>;

const FOOTPRINT: f32 = 0.25;
const SAME_SURFACE_RATIO: f32 = 1.1;

// `resample.rs`'s `same_surface`: depths within SAME_SURFACE_RATIO of the
// smaller, which is a surface; two skies agree, a sky and a point do not.
fn sh_same_surface(a: f32, b: f32) -> bool {
    if is_inf(a) || is_inf(b) {
        return bitcast<u32>(a) == bitcast<u32>(b);
    }
    let lo = min(a, b);
    let hi = max(a, b);
    return lo > 0.0 && hi <= lo * SAME_SURFACE_RATIO;
}

fn sh_luminance(c: vec4<f32>) -> f32 {
    return max(0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z, 0.0);
}

// Step 1: (r_t, aligned r_{t-1}) per pixel of frame t.
@compute @workgroup_size(256)
fn shading_ratio(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let x = thread_index(wid, nwg, lid);
    let w = sp.size.x;
    let h = sp.size.y;
    if x >= w * h {
        return;
    }
    let d = sh_depth[x];
    // `!(d > 0)` also takes NaN.
    if (sh_track[x] & 1u) == 1u || !(d > 0.0) {
        sh_ratio[x] = vec2<f32>(0.0);
        return;
    }
    let m = sh_motion[x];
    let p = vec2<f32>(f32(x % w) + 0.5 + m.x, f32(x / w) + 0.5 + m.y);
    if !(p.x >= 0.0 && p.x < f32(w) && p.y >= 0.0 && p.y < f32(h)) {
        sh_ratio[x] = vec2<f32>(0.0);
        return;
    }
    let cx = i32(p.x);
    let cy = i32(p.y);
    let lt = sh_luminance(sh_color[x]) + LUMA_FLOOR;
    // The bilinear footprint of the aligned position, on the pixel's own
    // surface.
    let bx = floor(p.x - 0.5);
    let by = floor(p.y - 0.5);
    let tx = p.x - 0.5 - bx;
    let ty = p.y - 0.5 - by;
    var lo = inf_f32();
    var hi = 0.0;
    for (var tap = 0u; tap < 4u; tap++) {
        let dx = i32(tap & 1u);
        let dy = i32(tap >> 1u);
        var weight = (1.0 - tx) * (1.0 - ty);
        if tap == 1u {
            weight = tx * (1.0 - ty);
        } else if tap == 2u {
            weight = (1.0 - tx) * ty;
        } else if tap == 3u {
            weight = tx * ty;
        }
        let sx = u32(clamp(i32(bx) + dx, 0, i32(w) - 1));
        let sy = u32(clamp(i32(by) + dy, 0, i32(h) - 1));
        let s = sy * w + sx;
        if weight < FOOTPRINT || !sh_same_surface(sh_prev_depth[s], d) {
            continue;
        }
        let l = sh_luminance(sh_prev_color[s]) + LUMA_FLOOR;
        lo = min(lo, l);
        hi = max(hi, l);
    }
    var best = 0.0;
    if lo > hi {
        best = 0.0;
    } else if lt < lo {
        best = log(lt / lo);
    } else if lt > hi {
        best = log(lt / hi);
    }
    var aligned = 0.0;
    if sp.flags.x == 1u {
        aligned = sh_prev_ratio[u32(cy) * w + u32(cx)].x;
    }
    let q = floor(clamp(best, -MAX_LOG_RATIO, MAX_LOG_RATIO) / QUANTUM + 0.5) * QUANTUM;
    sh_ratio[x] = vec2<f32>(q, aligned);
}

// Step 2's cost of displacement (dx, dy) for the block x0..x1, y0..y1:
// sum |r_t(x) - r_{t-1}(x - d)|.
fn sh_cost(x0: u32, y0: u32, x1: u32, y1: u32, dx: i32, dy: i32) -> f32 {
    let w = sp.size.x;
    let h = sp.size.y;
    var cost = 0.0;
    for (var y = y0; y < y1; y++) {
        for (var x = x0; x < x1; x++) {
            let sx = i32(x) - dx;
            let sy = i32(y) - dy;
            var before = 0.0;
            if sx >= 0 && sx < i32(w) && sy >= 0 && sy < i32(h) {
                before = sh_ratio[u32(sy) * w + u32(sx)].y;
            }
            cost += abs(sh_ratio[y * w + x].x - before);
        }
    }
    return cost;
}

// Step 2: the displacement of each block's change, [f.x, f.y, energy, 0].
@compute @workgroup_size(256)
fn shading_flow(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let b = thread_index(wid, nwg, lid);
    let w = sp.size.x;
    let h = sp.size.y;
    let bw = sp.size.z;
    if b >= bw * sp.size.w {
        return;
    }
    let x0 = (b % bw) * BLOCK;
    let y0 = (b / bw) * BLOCK;
    let x1 = min(x0 + BLOCK, w);
    let y1 = min(y0 + BLOCK, h);
    var energy = 0.0;
    for (var y = y0; y < y1; y++) {
        for (var x = x0; x < x1; x++) {
            energy += abs(sh_ratio[y * w + x].x);
        }
    }
    if !(energy >= MIN_ENERGY) {
        sh_flow[b] = vec4<f32>(0.0);
        return;
    }
    // The least cost, then the shortest displacement; over every even
    // displacement, then the pixel around the best.
    var best_cost = inf_f32();
    var best_len = 0x7fffffff;
    var best = vec2<i32>(0, 0);
    for (var dy = -SEARCH; dy <= SEARCH; dy += 2) {
        for (var dx = -SEARCH; dx <= SEARCH; dx += 2) {
            let c = sh_cost(x0, y0, x1, y1, dx, dy);
            let len = dx * dx + dy * dy;
            if c < best_cost || (c == best_cost && len < best_len) {
                best_cost = c;
                best_len = len;
                best = vec2<i32>(dx, dy);
            }
        }
    }
    let centre = best;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            if dx == 0 && dy == 0 {
                continue;
            }
            let d = centre + vec2<i32>(dx, dy);
            let c = sh_cost(x0, y0, x1, y1, d.x, d.y);
            let len = d.x * d.x + d.y * d.y;
            if c < best_cost || (c == best_cost && len < best_len) {
                best_cost = c;
                best_len = len;
                best = d;
            }
        }
    }
    if !(best_cost <= COHERENCE * energy) {
        sh_flow[b] = vec4<f32>(0.0);
        return;
    }
    sh_flow[b] = vec4<f32>(f32(best.x), f32(best.y), energy, 0.0);
}

// r_t at pixel (sx, sy) (the floor of a position), 0 outside the frame.
fn sh_ratio_nearest(sx: f32, sy: f32) -> f32 {
    let w = sp.size.x;
    let h = sp.size.y;
    if sx >= 0.0 && sx < f32(w) && sy >= 0.0 && sy < f32(h) {
        return sh_ratio[u32(sy) * w + u32(sx)].x;
    }
    return 0.0;
}

// r_t bilinearly at a continuous position (pixel centres at +0.5).
fn sh_ratio_bilinear(x: f32, y: f32) -> f32 {
    let bx = floor(x - 0.5);
    let by = floor(y - 0.5);
    let tx = x - 0.5 - bx;
    let ty = y - 0.5 - by;
    let top = sh_ratio_nearest(bx, by) * (1.0 - tx) + sh_ratio_nearest(bx + 1.0, by) * tx;
    let bottom = sh_ratio_nearest(bx, by + 1.0) * (1.0 - tx) + sh_ratio_nearest(bx + 1.0, by + 1.0) * tx;
    return top * (1.0 - ty) + bottom * ty;
}

// Step 3: the log change predicted over alpha intervals along f (whole
// intervals add the band a step on; a last fraction the band part of a
// step on, less the change ahead of it, kept between 0 and a whole step's).
fn sh_predict(px: u32, py: u32, f: vec2<f32>, alpha: f32) -> f32 {
    let cx = f32(px) + 0.5;
    let cy = f32(py) + 0.5;
    var predicted = 0.0;
    var left = clamp(alpha, 0.0, MAX_STEPS);
    var k = 1.0;
    while left > 0.0 {
        let whole = sh_ratio_nearest(floor(cx - k * f.x), floor(cy - k * f.y));
        if left >= 1.0 {
            predicted += whole;
        } else {
            let yx = cx - (k - 1.0) * f.x;
            let yy = cy - (k - 1.0) * f.y;
            let part = sh_ratio_bilinear(yx - left * f.x, yy - left * f.y);
            let ahead = sh_ratio_nearest(floor(yx), floor(yy));
            let change = part - (1.0 - left) * ahead;
            predicted += min(max(change, min(whole, 0.0)), max(whole, 0.0));
        }
        left -= 1.0;
        k += 1.0;
    }
    return predicted;
}

// Steps 3-4: the corrected colour at alpha.
@compute @workgroup_size(256)
fn shading_correct(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let x = thread_index(wid, nwg, lid);
    let w = sp.size.x;
    let h = sp.size.y;
    if x >= w * h {
        return;
    }
    let c = sh_color[x];
    sh_out[x] = c;
    if (sh_track[x] & 1u) == 1u {
        return;
    }
    let bw = i32(sp.size.z);
    let bh = i32(sp.size.w);
    let px = x % w;
    let py = x / w;
    let bx = i32(px / BLOCK);
    let by = i32(py / BLOCK);
    // A block with change of its own moves it by its own motion; one
    // without takes the motion of the neighbour (3x3) with the most change.
    var lender = sh_flow[u32(by * bw + bx)];
    if lender.z <= 0.0 {
        for (var dy = -1; dy <= 1; dy++) {
            for (var dx = -1; dx <= 1; dx++) {
                let nx = bx + dx;
                let ny = by + dy;
                if nx < 0 || ny < 0 || nx >= bw || ny >= bh {
                    continue;
                }
                let f = sh_flow[u32(ny * bw + nx)];
                if f.z > lender.z {
                    lender = f;
                }
            }
        }
    }
    if lender.z <= 0.0 {
        return;
    }
    let predicted = sh_predict(px, py, lender.xy, sp.alpha.x);
    let m = smoothstep(FOCUS_LOW, FOCUS_HIGH, abs(predicted));
    if m <= 0.0 {
        return;
    }
    let gain = exp(clamp(predicted, -MAX_LOG_RATIO, MAX_LOG_RATIO));
    let rgb = c.xyz + m * (c.xyz * gain - c.xyz);
    sh_out[x] = vec4<f32>(rgb, c.w);
}
