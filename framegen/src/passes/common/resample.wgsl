// Sub-pixel resampling on one surface: `resample.rs` operation by
// operation. A shader that uses it defines where the image comes from:
//   fn rs_color(k: u32) -> vec4<f32>   the source colour of pixel k
//   fn rs_depth(k: u32) -> f32         its sanitised depth
//   fn rs_size() -> vec2<i32>          the source's width and height

// Mirrors `resample.rs`.
const RESAMPLE_NEAREST: u32 = 0u;
const RESAMPLE_CATMULL_ROM: u32 = 2u;
const SAME_SURFACE_RATIO: f32 = 1.1;
const RESAMPLE_FLAT: f32 = 1.0 / 4096.0;

// `resample.rs` `same_surface`.
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
    let size = rs_size();
    let x = clamp(base.x + dx, 0, size.x - 1);
    let y = clamp(base.y + dy, 0, size.y - 1);
    return u32(y * size.x + x);
}

// The pixel containing `p`, clamped into the source (`sample.rs`
// `clamp_index`).
fn rs_clamp_index(p: vec2<f32>) -> u32 {
    let size = vec2<u32>(rs_size());
    let x = min(u32(max(p.x, 0.0)), size.x - 1u);
    let y = min(u32(max(p.y, 0.0)), size.y - 1u);
    return y * size.x + x;
}

// `resample.rs` `resample`: the source colour at `at` on pixel `own`'s
// surface.
fn resample_at(own: u32, at: vec2<f32>, mode: u32) -> vec3<f32> {
    let fallback = rs_color(own).xyz;
    if mode == RESAMPLE_NEAREST {
        return fallback;
    }
    let d0 = rs_depth(own);
    let q = at - 0.5;
    let basef = floor(q);
    let f = q - basef;
    let base = vec2<i32>(basef);
    // The inner 2×2 bounds every result; flat to the f16 output's rounding,
    // the pixel itself (`resample.rs` FLAT).
    let c0 = rs_color(tap_index(base, 0, 0));
    let c1 = rs_color(tap_index(base, 1, 0));
    let c2 = rs_color(tap_index(base, 0, 1));
    let c3 = rs_color(tap_index(base, 1, 1));
    let lo = min(min(c0, c1), min(c2, c3));
    let hi = max(max(c0, c1), max(c2, c3));
    if all((hi - lo) <= hi * RESAMPLE_FLAT) {
        return fallback;
    }
    if mode == RESAMPLE_CATMULL_ROM {
        var on_surface = true;
        for (var j = 0; j < 4; j++) {
            for (var i = 0; i < 4; i++) {
                on_surface = on_surface && same_surface(rs_depth(tap_index(base, i - 1, j - 1)), d0);
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
                    across += rs_color(tap_index(base, i - 1, j - 1)) * wx[i];
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
        if same_surface(rs_depth(k), d0) {
            let fx = select(1.0 - f.x, f.x, dx == 1);
            let fy = select(1.0 - f.y, f.y, dy == 1);
            sum += rs_color(k) * (fx * fy);
            weight += fx * fy;
        }
    }
    if weight > 1e-6 {
        return (sum / weight).xyz;
    }
    return fallback;
}
