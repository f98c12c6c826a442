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

@group(0) @binding(0) var<storage, read> sp: ShadingParams;
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

// Step 2, one workgroup per 8x8 block (`shading.rs`'s `flow_block`, the
// reference): the block's r_t and the window of aligned r_{t-1} around it
// are gathered once into workgroup memory, in quanta (0 outside the frame);
// the invocations then share the displacements' costs out among them. Sums
// of quanta are exact integers, so the least cost, then the shortest
// displacement, then the row order (`dy`, then `dx`) pick what the
// reference picks.

// Farthest a displacement reaches: the even search, then the pixel around
// its best.
const REACH: i32 = SEARCH + 1;
// Side of the window of r_{t-1} a block's search reads.
const SPAN: u32 = BLOCK + 2u * u32(REACH);
// Even displacements per axis (-SEARCH, -SEARCH + 2, ..., SEARCH) and in all.
const EVEN_SIDE: u32 = u32(SEARCH) + 1u;
const EVEN: u32 = EVEN_SIDE * EVEN_SIDE;
// Invocations per block (at least 9: the refinement's eight and the centre).
const FLOW_GROUP: u32 = 32u;

var<workgroup> fl_now: array<i32, BLOCK * BLOCK>;
var<workgroup> fl_before: array<i32, SPAN * SPAN>;
var<workgroup> fl_energy: i32;
// The least cost so far, then among its holders the least
// `|f|^2 << 8 | order`.
var<workgroup> fl_cost: atomic<u32>;
var<workgroup> fl_tie: atomic<u32>;

fn fl_quanta(v: f32) -> i32 {
    return i32(floor(v / QUANTUM + 0.5));
}

// sum |r_t(x) - r_{t-1}(x - d)| in quanta over the block's `cols` x `rows`.
fn fl_cost_of(d: vec2<i32>, cols: u32, rows: u32) -> u32 {
    var cost = 0u;
    for (var y = 0u; y < rows; y++) {
        let row = u32(i32(y) + REACH - d.y) * SPAN + u32(REACH - d.x);
        for (var x = 0u; x < cols; x++) {
            cost += u32(abs(fl_now[y * BLOCK + x] - fl_before[row + x]));
        }
    }
    return cost;
}

// Even displacement number `i` in row order.
fn fl_even(i: u32) -> vec2<i32> {
    return vec2<i32>(2 * i32(i % EVEN_SIDE) - SEARCH, 2 * i32(i / EVEN_SIDE) - SEARCH);
}

// [f.x, f.y, energy, 0] per block.
@compute @workgroup_size(FLOW_GROUP)
fn shading_flow(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let b = wid.y * nwg.x + wid.x;
    let w = sp.size.x;
    let h = sp.size.y;
    let bw = sp.size.z;
    // Uniform across the workgroup: the whole group leaves together.
    if b >= bw * sp.size.w {
        return;
    }
    let x0 = (b % bw) * BLOCK;
    let y0 = (b / bw) * BLOCK;
    let cols = min(x0 + BLOCK, w) - x0;
    let rows = min(y0 + BLOCK, h) - y0;
    for (var i = lid; i < BLOCK * BLOCK; i += FLOW_GROUP) {
        let x = i % BLOCK;
        let y = i / BLOCK;
        var v = 0;
        if x < cols && y < rows {
            v = fl_quanta(sh_ratio[(y0 + y) * w + x0 + x].x);
        }
        fl_now[i] = v;
    }
    workgroupBarrier();
    if lid == 0u {
        var e = 0;
        for (var i = 0u; i < BLOCK * BLOCK; i++) {
            e += abs(fl_now[i]);
        }
        fl_energy = e;
    }
    let energy = f32(workgroupUniformLoad(&fl_energy)) * QUANTUM;
    if energy < MIN_ENERGY {
        if lid == 0u {
            sh_flow[b] = vec4<f32>(0.0);
        }
        return;
    }
    // Only a block with a change to track reads the window.
    for (var i = lid; i < SPAN * SPAN; i += FLOW_GROUP) {
        let sx = i32(x0) - REACH + i32(i % SPAN);
        let sy = i32(y0) - REACH + i32(i / SPAN);
        var v = 0;
        if sx >= 0 && sx < i32(w) && sy >= 0 && sy < i32(h) {
            v = fl_quanta(sh_ratio[u32(sy) * w + u32(sx)].y);
        }
        fl_before[i] = v;
    }
    if lid == 0u {
        atomicStore(&fl_cost, 0xffffffffu);
        atomicStore(&fl_tie, 0xffffffffu);
    }
    workgroupBarrier();
    // Every even displacement, FLOW_GROUP apart; each invocation keeps its
    // least (cost, |f|^2 << 8 | order), and the workgroup the least of those.
    var cost = 0xffffffffu;
    var key = 0xffffffffu;
    for (var i = lid; i < EVEN; i += FLOW_GROUP) {
        let d = fl_even(i);
        let c = fl_cost_of(d, cols, rows);
        let k = (u32(d.x * d.x + d.y * d.y) << 8u) | i;
        if c < cost || (c == cost && k < key) {
            cost = c;
            key = k;
        }
    }
    atomicMin(&fl_cost, cost);
    workgroupBarrier();
    let even_best = atomicLoad(&fl_cost);
    if cost == even_best {
        atomicMin(&fl_tie, key);
    }
    workgroupBarrier();
    let centre = fl_even(atomicLoad(&fl_tie) & 0xffu);
    workgroupBarrier();
    if lid == 0u {
        atomicStore(&fl_tie, 0xffffffffu);
    }
    workgroupBarrier();
    // The eight pixels around it (order 1..8 in row order); the centre
    // (order 0) keeps its place on a tie.
    cost = 0xffffffffu;
    var d = centre;
    if lid < 8u {
        let k = i32(lid + u32(lid >= 4u));
        d = centre + vec2<i32>(k % 3 - 1, k / 3 - 1);
        cost = fl_cost_of(d, cols, rows);
        atomicMin(&fl_cost, cost);
    }
    workgroupBarrier();
    let best = atomicLoad(&fl_cost);
    if lid < 8u && cost == best {
        atomicMin(&fl_tie, (u32(d.x * d.x + d.y * d.y) << 8u) | (lid + 1u));
    }
    if lid == 8u && even_best == best {
        atomicMin(&fl_tie, u32(centre.x * centre.x + centre.y * centre.y) << 8u);
    }
    workgroupBarrier();
    if lid == 0u {
        let order = atomicLoad(&fl_tie) & 0xffu;
        var f = centre;
        if order > 0u {
            let k = i32(order - 1u + u32(order > 4u));
            f = centre + vec2<i32>(k % 3 - 1, k / 3 - 1);
        }
        if f32(best) * QUANTUM > COHERENCE * energy {
            sh_flow[b] = vec4<f32>(0.0);
        } else {
            sh_flow[b] = vec4<f32>(f32(f.x), f32(f.y), energy, 0.0);
        }
    }
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
