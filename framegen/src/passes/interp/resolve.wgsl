// GeoMotionGen pass 7, two-sided: fuse the current and previous frames.
// See `resolve.rs`; the resampling is `resample.wgsl`'s.

struct ResolveParams {
    // width, height, the colour filter (`Resample::code`), 0.
    size: vec4<u32>,
    alpha: vec4<f32>,
};

@group(0) @binding(0) var<storage, read> rp: ResolveParams;
@group(0) @binding(1) var<storage, read> cur_color: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> cur_depth: array<f32>;
@group(0) @binding(3) var<storage, read> prev_color: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> prev_depth: array<f32>;
@group(0) @binding(5) var<storage, read_write> out_color: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> out_depth: array<f32>;
@group(0) @binding(7) var<storage, read_write> out_motion: array<vec2<f32>>;
@group(0) @binding(8) var<storage, read_write> out_mask: array<u32>;

// Which frame `resample.wgsl` reads: the current one unless set.
var<private> from_previous: bool;

fn rs_color(k: u32) -> vec4<f32> {
    if from_previous {
        return prev_color[k];
    }
    return cur_color[k];
}

fn rs_depth(k: u32) -> f32 {
    if from_previous {
        return prev_depth[k];
    }
    return cur_depth[k];
}

fn rs_size() -> vec2<i32> {
    return vec2<i32>(rp.size.xy);
}

// `resolve.rs` `take`: colour (w = depth) of one side at `at`.
fn take(previous: bool, at: vec2<f32>) -> vec4<f32> {
    from_previous = previous;
    let own = rs_clamp_index(at);
    return vec4<f32>(resample_at(own, at, rp.size.z), rs_depth(own));
}

// `resolve.rs` `mix`.
fn mix_depth(a: f32, b: f32, alpha: f32) -> f32 {
    if bitcast<u32>(a) == bitcast<u32>(b) {
        return a;
    }
    return a * (1.0 - alpha) + b * alpha;
}

@compute @workgroup_size(256)
fn interp_resolve(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let t = thread_index(wid, nwg, lid);
    let w = rp.size.x;
    if t >= w * rp.size.y {
        return;
    }
    let alpha = rp.alpha.x;
    let center = vec2<f32>(f32(t % w) + 0.5, f32(t / w) + 0.5);
    let size = vec2<f32>(f32(w), f32(rp.size.y));
    let m = out_motion[t] * size;
    let before = center + m * alpha;
    var r: vec4<f32>;
    if out_mask[t] != WARPED_MASK {
        r = take(true, before);
    } else {
        // `resolve.rs` `fetch`.
        let now = center - m * (1.0 - alpha);
        var both = false;
        if all(before >= vec2<f32>(0.0)) && all(before < size) {
            from_previous = false;
            let d_now = rs_depth(rs_clamp_index(now));
            from_previous = true;
            let d_before = rs_depth(rs_clamp_index(before));
            both = same_surface(d_before, d_now);
        }
        let c = take(false, now);
        r = c;
        if both {
            let p = take(true, before);
            r = vec4<f32>(p.xyz * (1.0 - alpha) + c.xyz * alpha, mix_depth(p.w, c.w, alpha));
        }
    }
    out_color[t] = vec4<f32>(r.xyz, 1.0);
    out_depth[t] = r.w;
    out_motion[t] = m * alpha;
}
